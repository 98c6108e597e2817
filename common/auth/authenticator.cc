#include "common/auth/authenticator.h"

#include <openssl/crypto.h>
#include <sys/stat.h>

#include <spdlog/spdlog.h>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"
#include "common/core/status.h"

namespace instascene::auth {
namespace {

const absl::Status kUnauthenticated = absl::UnauthenticatedError(
    "a valid bearer token is required (metadata \"authorization: Bearer isk_...\"; "
    "`instascene token create` makes one)");

bool SameSecret(const std::string& a_hex, const std::string& b_hex) {
  return a_hex.size() == b_hex.size() &&
         CRYPTO_memcmp(a_hex.data(), b_hex.data(), a_hex.size()) == 0;
}

}  // namespace

std::shared_ptr<Authenticator> Authenticator::Disabled() {
  return std::shared_ptr<Authenticator>(new Authenticator(false, "", {}));
}

absl::StatusOr<std::shared_ptr<Authenticator>> Authenticator::FromFile(
    const std::string& path, std::chrono::milliseconds reload_check) {
  std::shared_ptr<Authenticator> auth(new Authenticator(true, path, reload_check));
  ASSIGN_OR_RETURN(auth->file_, LoadTokenFile(path));
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) {
    auth->file_mtime_ns_ = int64_t{st.st_mtim.tv_sec} * 1000000000 + st.st_mtim.tv_nsec;
    auth->file_size_ = st.st_size;
  }
  auth->last_check_ = std::chrono::steady_clock::now();
  return auth;
}

absl::StatusOr<std::string> Authenticator::AddProcessToken(Role role) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (;;) {
    TokenRecord r;
    ASSIGN_OR_RETURN(std::string token, GenerateToken(&r));
    if (process_tokens_.count(r.id) || file_.Find(r.id)) continue;
    r.role = role;
    r.note = "process token";
    process_tokens_[r.id] = r;
    return token;
  }
}

void Authenticator::MaybeReload() {
  const auto now = std::chrono::steady_clock::now();
  if (now - last_check_ < reload_check_) return;
  last_check_ = now;
  struct stat st {};
  if (::stat(path_.c_str(), &st) != 0) {
    if (file_size_ != -2) spdlog::error("token file {} is gone: no file token is accepted", path_);
    file_ = TokenFile{};
    file_size_ = -2;
    return;
  }
  const int64_t mtime = int64_t{st.st_mtim.tv_sec} * 1000000000 + st.st_mtim.tv_nsec;
  if (mtime == file_mtime_ns_ && st.st_size == file_size_) return;
  absl::StatusOr<TokenFile> loaded = LoadTokenFile(path_);
  if (!loaded.ok()) {
    spdlog::error("token file {} not reloaded (the previous tokens stay valid): {}", path_,
                  std::string(loaded.status().message()));
    return;
  }
  file_ = *std::move(loaded);
  file_mtime_ns_ = mtime;
  file_size_ = st.st_size;
  spdlog::info("token file {} reloaded: {} tokens", path_, file_.tokens.size());
}

absl::StatusOr<Identity> Authenticator::Authenticate(absl::string_view authorization) {
  if (!enabled_) return Identity::Unrestricted();
  absl::string_view value = absl::StripAsciiWhitespace(authorization);
  if (!absl::ConsumePrefix(&value, "Bearer ") && !absl::ConsumePrefix(&value, "bearer "))
    return kUnauthenticated;
  std::string id, secret;
  if (!SplitToken(value, &id, &secret).ok()) return kUnauthenticated;
  const std::string hash = HashSecret(secret);
  std::lock_guard<std::mutex> lock(mutex_);
  MaybeReload();
  const TokenRecord* record = file_.Find(id);
  if (record == nullptr) {
    auto it = process_tokens_.find(id);
    if (it != process_tokens_.end()) record = &it->second;
  }
  if (record == nullptr || record->revoked_unix_ms != 0 || !SameSecret(record->secret_sha256, hash))
    return kUnauthenticated;
  Identity who;
  who.token_id = record->id;
  who.tenant = record->tenant;
  who.role = record->role;
  return who;
}

absl::StatusOr<Identity> Authenticator::Authorize(const grpc::ServerContext* context,
                                                  std::initializer_list<Role> allowed) {
  if (!enabled_) return Identity::Unrestricted();
  const auto& metadata = context->client_metadata();
  const auto it = metadata.find(kAuthorizationHeader);
  if (it == metadata.end()) return kUnauthenticated;
  ASSIGN_OR_RETURN(Identity who,
                   Authenticate(absl::string_view(it->second.data(), it->second.size())));
  for (Role r : allowed)
    if (r == who.role) return who;
  return absl::PermissionDeniedError(
      absl::StrCat("a ", RoleName(who.role), " token may not call this method"));
}

absl::StatusOr<Identity> Authorize(Authenticator* auth, const grpc::ServerContext* context,
                                   std::initializer_list<Role> allowed) {
  if (auth == nullptr) return Identity::Unrestricted();
  return auth->Authorize(context, allowed);
}

}  // namespace instascene::auth
