// common/store/testing/s3_server.h: a real S3-compatible server for tests, started by the test
// itself: moto (the `moto` Python package in the image) on a free loopback port with SigV4
// authentication enforced, a bucket and an IAM user's key created for the test
// (s3_test_server.py). The server exits when this object goes away, and also when the test
// process dies (it serves until its standard input closes), so nothing outlives a test.
#pragma once

#include <sys/types.h>

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "common/store/s3_client.h"

namespace instascene::store::testing {

class S3Server {
 public:
  static absl::StatusOr<std::unique_ptr<S3Server>> Start(
      const std::string& bucket = "instascene-test");
  ~S3Server();

  const std::string& endpoint() const { return endpoint_; }  // http://127.0.0.1:PORT
  const std::string& bucket() const { return bucket_; }
  const S3Credentials& credentials() const { return credentials_; }
  // A location in the bucket under `prefix`, path-style, '/' literal in query values (moto).
  S3Location Location(const std::string& prefix) const;

 private:
  S3Server() = default;
  pid_t pid_ = -1;
  int stdin_fd_ = -1;
  std::string endpoint_, bucket_;
  S3Credentials credentials_;
};

// The test binary's one server, started by the `main` of s3_test_main.cc (link the object library
// instascene_s3_test_main), which runs every test after it started.
S3Server& SharedS3Server();

}  // namespace instascene::store::testing
