// common/auth/tokens.h: bearer tokens per tenant, kept in a token file (JSON) that stores only
// each token's SHA-256, never the token. A token reads "isk_<id>_<secret>": the id (12 hex) finds
// the record, the secret (64 hex, 256 random bits from the OS) is checked against the stored hash
// in constant time. Roles: client (its tenant's scenes), worker (leases and the store), admin
// (everything, plus monitoring). `instascene token create|revoke|list` edits the file; servers
// re-read it when it changes, so a revocation takes effect at the next call, without a restart.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace instascene::auth {

enum class Role { kClient = 1, kWorker, kAdmin };
const char* RoleName(Role role);  // "client", "worker", "admin"
absl::StatusOr<Role> ParseRole(absl::string_view name);

// Tenant names: 1-32 of [a-z0-9-], starting with a letter or digit. Client tokens need one;
// worker and admin tokens have none ("").
absl::Status ValidateTenant(absl::string_view tenant);

struct TokenRecord {
  std::string id;      // 12 lower-case hex
  std::string tenant;  // "" for worker and admin tokens
  Role role = Role::kClient;
  std::string secret_sha256;  // hex SHA-256 of the secret part
  std::string note;           // free text (who or what holds it), at most 200 bytes
  int64_t created_unix_ms = 0;
  int64_t revoked_unix_ms = 0;  // 0 = valid
};

struct TokenFile {
  std::vector<TokenRecord> tokens;

  static absl::StatusOr<TokenFile> Parse(absl::string_view json, const std::string& what);
  std::string Serialize() const;
  const TokenRecord* Find(absl::string_view id) const;
};

// Reads a token file (NotFound when it does not exist; at most 16 MB).
absl::StatusOr<TokenFile> LoadTokenFile(const std::string& path);

// Adds a token to the file (created, mode 0600, with its folder, if absent; written atomically,
// under a lock file beside it) and returns the bearer string: the only time it is ever shown.
absl::StatusOr<std::string> CreateToken(const std::string& path, Role role,
                                        const std::string& tenant, const std::string& note,
                                        TokenRecord* created = nullptr);
// Marks a token revoked (kept in the file, so `list` shows when). NotFound for an unknown id.
absl::Status RevokeToken(const std::string& path, const std::string& id);

// Splits "isk_<id>_<secret>" (surrounding white space ignored); InvalidArgument otherwise.
absl::Status SplitToken(absl::string_view token, std::string* id, std::string* secret);
std::string HashSecret(absl::string_view secret);  // hex SHA-256
// A new random token; fills the record's id and secret_sha256 (the caller sets the rest).
absl::StatusOr<std::string> GenerateToken(TokenRecord* record);

// Reads a token from a file (first line, trimmed); InvalidArgument if it is not one.
absl::StatusOr<std::string> ReadTokenFile(const std::string& path);
// Writes a token to a file readable by its owner only (0600), atomically.
absl::Status WriteTokenFile(const std::string& path, const std::string& token);

}  // namespace instascene::auth
