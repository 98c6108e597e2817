#include "common/store/digest.h"

#include <cstdio>
#include <fstream>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

namespace instascene::store {

std::string Digest::ToString() const { return absl::StrCat(hash, "/", size_bytes); }

Sha256::Sha256() : ctx_(EVP_MD_CTX_new()) { EVP_DigestInit_ex(ctx_.get(), EVP_sha256(), nullptr); }

void Sha256::Update(absl::string_view bytes) {
  EVP_DigestUpdate(ctx_.get(), bytes.data(), bytes.size());
}

std::string Sha256::HexDigest() {
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  EVP_DigestFinal_ex(ctx_.get(), md, &len);
  static constexpr char kHex[] = "0123456789abcdef";
  std::string hex(2 * len, '0');
  for (unsigned int i = 0; i < len; ++i) {
    hex[2 * i] = kHex[md[i] >> 4];
    hex[2 * i + 1] = kHex[md[i] & 15];
  }
  return hex;
}

Digest ComputeDigest(absl::string_view bytes) {
  Sha256 sha;
  sha.Update(bytes);
  return Digest{sha.HexDigest(), static_cast<int64_t>(bytes.size())};
}

absl::StatusOr<Digest> DigestFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  Sha256 sha;
  std::vector<char> buffer(1 << 20);
  int64_t size = 0;
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    const std::streamsize n = in.gcount();
    if (n <= 0) break;
    sha.Update(absl::string_view(buffer.data(), static_cast<size_t>(n)));
    size += n;
  }
  if (in.bad()) return absl::DataLossError(absl::StrCat(path, ": read error"));
  return Digest{sha.HexDigest(), size};
}

absl::Status ValidateDigest(const Digest& digest) {
  if (digest.hash.size() != 64)
    return absl::InvalidArgumentError(
        absl::StrCat("digest hash '", digest.hash, "' is not 64 hex characters"));
  for (char c : digest.hash) {
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f')))
      return absl::InvalidArgumentError(
          absl::StrCat("digest hash '", digest.hash, "' is not lower-case hex"));
  }
  if (digest.size_bytes < 0)
    return absl::InvalidArgumentError(absl::StrCat("digest size ", digest.size_bytes, " < 0"));
  return absl::OkStatus();
}

absl::StatusOr<Digest> ParseDigest(absl::string_view text) {
  std::vector<absl::string_view> parts = absl::StrSplit(text, '/');
  Digest d;
  if (parts.size() != 2 || !absl::SimpleAtoi(parts[1], &d.size_bytes))
    return absl::InvalidArgumentError(absl::StrCat("'", text, "' is not a digest (hash/size)"));
  d.hash = std::string(parts[0]);
  if (absl::Status s = ValidateDigest(d); !s.ok()) return s;
  return d;
}

}  // namespace instascene::store
