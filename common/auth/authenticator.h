// common/auth/authenticator.h: checks the bearer token of every gRPC call against the token file
// (common/auth/tokens.h) and the method's allowed roles. Each service method calls Authorize
// first; a missing, malformed, unknown or revoked token is UNAUTHENTICATED, a role the method
// does not allow PERMISSION_DENIED (neither says which tokens exist). The file is re-read when it
// changes (its modification time and size, one stat per call unless `reload_check` spaces the
// checks): new and revoked tokens take effect at the next call, without a restart; a file that no
// longer parses keeps the last good set and logs why. Thread-safe.
#pragma once

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <initializer_list>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "absl/status/statusor.h"
#include "common/auth/identity.h"
#include "common/auth/tokens.h"

namespace instascene::auth {

inline constexpr char kAuthorizationHeader[] = "authorization";  // "Bearer isk_..."

class Authenticator {
 public:
  // Authentication off: every caller is an unrestricted admin (`--no-auth`, library tests).
  static std::shared_ptr<Authenticator> Disabled();
  // Tokens from `path`; NotFound when the file does not exist.
  static absl::StatusOr<std::shared_ptr<Authenticator>> FromFile(
      const std::string& path,
      std::chrono::milliseconds reload_check = std::chrono::milliseconds(0));

  bool enabled() const { return enabled_; }
  // A token valid in this process only, never written anywhere (a node's own workers reach its
  // scheduler over the in-process channel with it). Returns the bearer string.
  absl::StatusOr<std::string> AddProcessToken(Role role);

  // The identity behind an "authorization" header value ("Bearer <token>").
  absl::StatusOr<Identity> Authenticate(absl::string_view authorization);
  // Authenticate the call's metadata, then check the role: UNAUTHENTICATED / PERMISSION_DENIED.
  absl::StatusOr<Identity> Authorize(const grpc::ServerContext* context,
                                     std::initializer_list<Role> allowed);

 private:
  Authenticator(bool enabled, std::string path, std::chrono::milliseconds reload_check)
      : enabled_(enabled), path_(std::move(path)), reload_check_(reload_check) {}
  void MaybeReload();

  const bool enabled_;
  const std::string path_;
  const std::chrono::milliseconds reload_check_;
  std::mutex mutex_;
  TokenFile file_;
  std::map<std::string, TokenRecord> process_tokens_;  // by id
  std::chrono::steady_clock::time_point last_check_{};
  int64_t file_mtime_ns_ = -1, file_size_ = -1;
};

// Authorize against a possibly null authenticator (null = off: an unrestricted admin).
absl::StatusOr<Identity> Authorize(Authenticator* auth, const grpc::ServerContext* context,
                                   std::initializer_list<Role> allowed);

}  // namespace instascene::auth
