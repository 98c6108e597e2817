#include "common/store/testing/s3_server.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

#ifndef INSTASCENE_S3_TEST_SERVER
#error "INSTASCENE_S3_TEST_SERVER must name s3_test_server.py"
#endif

namespace instascene::store::testing {

absl::StatusOr<std::unique_ptr<S3Server>> S3Server::Start(const std::string& bucket) {
  int to_child[2], from_child[2];
  if (::pipe2(to_child, O_CLOEXEC) != 0 || ::pipe2(from_child, O_CLOEXEC) != 0)
    return absl::InternalError("pipe failed");
  const pid_t pid = ::fork();
  if (pid < 0) return absl::InternalError("fork failed");
  if (pid == 0) {
    ::dup2(to_child[0], 0);
    ::dup2(from_child[1], 1);
    const char* script = INSTASCENE_S3_TEST_SERVER;
    ::execlp("python3", "python3", script, bucket.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ::close(to_child[0]);
  ::close(from_child[1]);
  std::unique_ptr<S3Server> s(new S3Server());
  s->pid_ = pid;
  s->stdin_fd_ = to_child[1];
  // The server announces itself with one line once it serves (or exits on failure: EOF).
  std::string line;
  char c;
  while (::read(from_child[0], &c, 1) == 1 && c != '\n') line += c;
  ::close(from_child[0]);
  const std::vector<std::string> words = absl::StrSplit(line, ' ');
  if (words.size() != 5 || words[0] != "READY")
    return absl::FailedPreconditionError(absl::StrCat(
        "the S3 test server did not start (needs python3 with moto and boto3, as in the image): '",
        line.substr(0, 200), "'"));
  s->endpoint_ = words[1];
  s->bucket_ = words[2];
  s->credentials_ = {words[3], words[4], ""};
  return s;
}

S3Server::~S3Server() {
  if (stdin_fd_ >= 0) ::close(stdin_fd_);  // the server's cue to stop
  if (pid_ > 0) {
    int status = 0;
    ::waitpid(pid_, &status, 0);
  }
}

S3Location S3Server::Location(const std::string& prefix) const {
  S3Location loc;
  loc.endpoint = endpoint_;
  loc.bucket = bucket_;
  loc.prefix = prefix.empty() ? "" : (prefix.back() == '/' ? prefix : prefix + "/");
  loc.path_style = true;
  loc.query_slash_literal = true;  // moto's canonical form (s3_client.h)
  return loc;
}

}  // namespace instascene::store::testing
