#include "common/auth/tokens.h"

#include <fcntl.h>
#include <openssl/crypto.h>
#include <openssl/rand.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <functional>

#include <nlohmann/json.hpp>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"
#include "common/core/file_io.h"
#include "common/core/file_lock.h"
#include "common/core/status.h"
#include "common/store/blob_store.h"
#include "common/store/digest.h"

namespace instascene::auth {
namespace fs = std::filesystem;
namespace {

constexpr size_t kMaxTokenFileBytes = size_t{16} << 20;
constexpr size_t kIdHex = 12, kSecretHex = 64;

bool IsLowerHex(absl::string_view s) {
  for (char c : s)
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  return true;
}

absl::StatusOr<std::string> RandomHex(size_t hex_digits) {
  std::string bytes(hex_digits / 2, '\0');
  if (RAND_bytes(reinterpret_cast<unsigned char*>(bytes.data()), static_cast<int>(bytes.size())) !=
      1)
    return absl::UnavailableError("the system's random source failed");
  static constexpr char kHex[] = "0123456789abcdef";
  std::string hex;
  for (unsigned char c : bytes) {
    hex.push_back(kHex[c >> 4]);
    hex.push_back(kHex[c & 15]);
  }
  return hex;
}

int64_t NowUnixMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// Writes `bytes` to `path` atomically with mode 0600 (the temp file is created 0600, then renamed).
absl::Status WritePrivateFile(const std::string& path, absl::string_view bytes) {
  std::error_code ec;
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty()) fs::create_directories(parent, ec);
  if (ec) return absl::UnavailableError(absl::StrCat(parent.string(), ": ", ec.message()));
  const std::string temp = absl::StrCat(path, ".tmp.", ::getpid());
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd < 0) return absl::UnavailableError(absl::StrCat(temp, ": cannot create"));
  ::close(fd);
  absl::Status s = WriteAndSync(temp, bytes);
  if (s.ok()) s = RenameDurably(temp, path);
  if (!s.ok()) fs::remove(temp, ec);
  return s;
}

// Runs `edit` on the file's contents (empty when absent) under the lock file beside it.
absl::Status EditTokenFile(const std::string& path,
                           const std::function<absl::Status(TokenFile&)>& edit) {
  std::error_code ec;
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty()) fs::create_directories(parent, ec);
  ASSIGN_OR_RETURN(FileLock lock, FileLock::Acquire(path + ".lock", "token file " + path));
  TokenFile file;
  if (absl::StatusOr<TokenFile> loaded = LoadTokenFile(path); loaded.ok()) {
    file = *std::move(loaded);
  } else if (!absl::IsNotFound(loaded.status())) {
    return loaded.status();
  }
  RETURN_IF_ERROR(edit(file));
  return WritePrivateFile(path, file.Serialize());
}

}  // namespace

const char* RoleName(Role role) {
  switch (role) {
    case Role::kClient:
      return "client";
    case Role::kWorker:
      return "worker";
    case Role::kAdmin:
      return "admin";
  }
  return "?";
}

absl::StatusOr<Role> ParseRole(absl::string_view name) {
  for (Role r : {Role::kClient, Role::kWorker, Role::kAdmin})
    if (name == RoleName(r)) return r;
  return absl::InvalidArgumentError(
      absl::StrCat("role '", name.substr(0, 40), "': expected client, worker or admin"));
}

absl::Status ValidateTenant(absl::string_view tenant) {
  // One rule for the store's grant paths and for tokens (the store sits below auth).
  if (!store::CheckTenantName(tenant).ok())
    return absl::InvalidArgumentError(
        absl::StrCat("tenant '", tenant.substr(0, 40),
                     "': 1-32 characters of a-z, 0-9 and '-', not starting with '-'"));
  return absl::OkStatus();
}

const TokenRecord* TokenFile::Find(absl::string_view id) const {
  for (const TokenRecord& t : tokens)
    if (t.id == id) return &t;
  return nullptr;
}

absl::StatusOr<TokenFile> TokenFile::Parse(absl::string_view json, const std::string& what) {
  const nlohmann::json j = nlohmann::json::parse(json, nullptr, false);
  auto bad = [&](const std::string& why) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": ", why));
  };
  if (j.is_discarded() || !j.is_object()) return bad("not a JSON object");
  if (!j.contains("format") || !j["format"].is_number_integer() || j["format"] != 1)
    return bad("\"format\" must be 1");
  if (!j.contains("tokens") || !j["tokens"].is_array()) return bad("\"tokens\" must be an array");
  TokenFile file;
  for (const nlohmann::json& t : j["tokens"]) {
    if (!t.is_object()) return bad("a token entry is not an object");
    auto str = [&](const char* key) -> absl::StatusOr<std::string> {
      if (!t.contains(key) || !t[key].is_string())
        return bad(absl::StrCat("a token lacks the string \"", key, "\""));
      return t[key].get<std::string>();
    };
    auto num = [&](const char* key) -> absl::StatusOr<int64_t> {
      if (!t.contains(key)) return 0;
      if (!t[key].is_number_integer()) return bad(absl::StrCat("\"", key, "\" is not an integer"));
      return t[key].get<int64_t>();
    };
    TokenRecord r;
    ASSIGN_OR_RETURN(r.id, str("id"));
    ASSIGN_OR_RETURN(r.tenant, str("tenant"));
    ASSIGN_OR_RETURN(std::string role, str("role"));
    ASSIGN_OR_RETURN(r.role, ParseRole(role));
    ASSIGN_OR_RETURN(r.secret_sha256, str("secret_sha256"));
    ASSIGN_OR_RETURN(r.note, str("note"));
    ASSIGN_OR_RETURN(r.created_unix_ms, num("created_unix_ms"));
    ASSIGN_OR_RETURN(r.revoked_unix_ms, num("revoked_unix_ms"));
    if (r.id.size() != kIdHex || !IsLowerHex(r.id)) return bad("a token id is not 12 hex digits");
    if (r.secret_sha256.size() != 64 || !IsLowerHex(r.secret_sha256))
      return bad(absl::StrCat("token ", r.id, ": secret_sha256 is not a SHA-256"));
    if (r.role == Role::kClient) {
      if (absl::Status s = ValidateTenant(r.tenant); !s.ok())
        return bad(absl::StrCat("token ", r.id, ": ", s.message()));
    } else if (!r.tenant.empty()) {
      return bad(absl::StrCat("token ", r.id, ": only client tokens have a tenant"));
    }
    if (file.Find(r.id)) return bad(absl::StrCat("token id ", r.id, " appears twice"));
    file.tokens.push_back(std::move(r));
  }
  return file;
}

std::string TokenFile::Serialize() const {
  nlohmann::json list = nlohmann::json::array();
  for (const TokenRecord& t : tokens)
    list.push_back({{"id", t.id},
                    {"tenant", t.tenant},
                    {"role", RoleName(t.role)},
                    {"secret_sha256", t.secret_sha256},
                    {"note", t.note},
                    {"created_unix_ms", t.created_unix_ms},
                    {"revoked_unix_ms", t.revoked_unix_ms}});
  return nlohmann::json{{"format", 1}, {"tokens", list}}.dump(2) + "\n";
}

absl::StatusOr<TokenFile> LoadTokenFile(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return absl::NotFoundError(absl::StrCat("no token file ", path));
  ASSIGN_OR_RETURN(std::string bytes, ReadFileBounded(path, kMaxTokenFileBytes));
  return TokenFile::Parse(bytes, path);
}

std::string HashSecret(absl::string_view secret) { return store::ComputeDigest(secret).hash; }

absl::StatusOr<std::string> GenerateToken(TokenRecord* record) {
  ASSIGN_OR_RETURN(record->id, RandomHex(kIdHex));
  ASSIGN_OR_RETURN(std::string secret, RandomHex(kSecretHex));
  record->secret_sha256 = HashSecret(secret);
  return absl::StrCat("isk_", record->id, "_", secret);
}

absl::Status SplitToken(absl::string_view token, std::string* id, std::string* secret) {
  token = absl::StripAsciiWhitespace(token);
  const absl::Status bad = absl::InvalidArgumentError(
      "a token reads isk_<12 hex>_<64 hex> (as `instascene token create` prints it)");
  if (!absl::ConsumePrefix(&token, "isk_") || token.size() != kIdHex + 1 + kSecretHex ||
      token[kIdHex] != '_')
    return bad;
  const absl::string_view i = token.substr(0, kIdHex), s = token.substr(kIdHex + 1);
  if (!IsLowerHex(i) || !IsLowerHex(s)) return bad;
  *id = std::string(i);
  *secret = std::string(s);
  return absl::OkStatus();
}

absl::StatusOr<std::string> CreateToken(const std::string& path, Role role,
                                        const std::string& tenant, const std::string& note,
                                        TokenRecord* created) {
  if (role == Role::kClient) {
    RETURN_IF_ERROR(ValidateTenant(tenant));
  } else if (!tenant.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(RoleName(role), " tokens have no tenant (they see every tenant)"));
  }
  if (note.size() > 200) return absl::InvalidArgumentError("note: at most 200 bytes");
  std::string token;
  RETURN_IF_ERROR(EditTokenFile(path, [&](TokenFile& file) -> absl::Status {
    TokenRecord r;
    do {
      ASSIGN_OR_RETURN(token, GenerateToken(&r));
    } while (file.Find(r.id));
    r.tenant = tenant;
    r.role = role;
    r.note = note;
    r.created_unix_ms = NowUnixMs();
    if (created) *created = r;
    file.tokens.push_back(std::move(r));
    return absl::OkStatus();
  }));
  return token;
}

absl::Status RevokeToken(const std::string& path, const std::string& id) {
  return EditTokenFile(path, [&](TokenFile& file) -> absl::Status {
    for (TokenRecord& t : file.tokens) {
      if (t.id != id) continue;
      if (t.revoked_unix_ms == 0) t.revoked_unix_ms = NowUnixMs();
      return absl::OkStatus();
    }
    return absl::NotFoundError(absl::StrCat("no token ", id.substr(0, 40), " in ", path));
  });
}

absl::StatusOr<std::string> ReadTokenFile(const std::string& path) {
  ASSIGN_OR_RETURN(std::string bytes, ReadFileBounded(path, 4096));
  std::string id, secret;
  const std::string line = bytes.substr(0, bytes.find('\n'));
  if (absl::Status s = SplitToken(line, &id, &secret); !s.ok())
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", s.message()));
  return std::string(absl::StripAsciiWhitespace(line));
}

absl::Status WriteTokenFile(const std::string& path, const std::string& token) {
  return WritePrivateFile(path, token + "\n");
}

}  // namespace instascene::auth
