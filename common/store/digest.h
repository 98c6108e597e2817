// common/store/digest.h: content digests (SHA-256 of a blob's bytes + its size), the names of
// everything in the content-addressed store. Value types; Sha256 is not thread-safe (one per hash).
#pragma once

#include <openssl/evp.h>

#include <cstdint>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace instascene::store {

struct Digest {
  std::string hash;  // 64 lower-case hex characters
  int64_t size_bytes = 0;

  std::string ToString() const;  // "hash/size", the form used in logs, CLI and manifests
  bool operator==(const Digest&) const = default;
  auto operator<=>(const Digest&) const = default;
};

// Incremental SHA-256 (OpenSSL EVP).
class Sha256 {
 public:
  Sha256();
  void Update(absl::string_view bytes);
  std::string HexDigest();  // finishes; the object must not be updated afterwards

 private:
  struct Free {
    void operator()(EVP_MD_CTX* ctx) const { EVP_MD_CTX_free(ctx); }
  };
  std::unique_ptr<EVP_MD_CTX, Free> ctx_;
};

Digest ComputeDigest(absl::string_view bytes);
// Streams the file; errors name the path.
absl::StatusOr<Digest> DigestFile(const std::string& path);

// A well-formed digest: 64 lower-case hex characters and a size in [0, max_size].
absl::Status ValidateDigest(const Digest& digest);
// Parses "hash/size".
absl::StatusOr<Digest> ParseDigest(absl::string_view text);

}  // namespace instascene::store
