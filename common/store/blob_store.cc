#include "common/store/blob_store.h"

#include <cstdio>
#include <fstream>
#include <tuple>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "common/core/file_io.h"
#include "common/core/status.h"

namespace instascene::store {

absl::Status StoreOptions::Validate() const {
  if (max_blob_bytes <= 0) return absl::InvalidArgumentError("max_blob_bytes must be > 0");
  if (max_batch_bytes <= 0) return absl::InvalidArgumentError("max_batch_bytes must be > 0");
  if (upload_ttl_seconds < 0) return absl::InvalidArgumentError("upload_ttl_seconds must be >= 0");
  if (tenant_quota_bytes < 0) return absl::InvalidArgumentError("tenant_quota_bytes must be >= 0");
  return absl::OkStatus();
}

absl::Status CheckWritable(const Digest& digest, const StoreOptions& options) {
  RETURN_IF_ERROR(ValidateDigest(digest));
  if (digest.size_bytes > options.max_blob_bytes)
    return absl::ResourceExhaustedError(absl::StrCat("blob ", digest.ToString(),
                                                     " is larger than the store's limit of ",
                                                     options.max_blob_bytes, " bytes"));
  return absl::OkStatus();
}

absl::Status VerifyBlobBytes(const Digest& digest, absl::string_view bytes) {
  if (static_cast<int64_t>(bytes.size()) != digest.size_bytes)
    return absl::InvalidArgumentError(absl::StrCat("blob ", digest.ToString(), ": got ",
                                                   bytes.size(), " bytes, digest says ",
                                                   digest.size_bytes));
  const Digest actual = ComputeDigest(bytes);
  if (actual.hash != digest.hash)
    return absl::InvalidArgumentError(absl::StrCat("digest mismatch: claimed ", digest.hash,
                                                   ", bytes hash to ", actual.hash,
                                                   "; nothing stored"));
  return absl::OkStatus();
}

absl::Status CheckAppend(const Digest& digest, int64_t offset, int64_t committed, size_t bytes) {
  if (offset != committed)
    return absl::FailedPreconditionError(
        absl::StrCat("blob ", digest.ToString(), ": write at offset ", offset,
                     " but the upload has ", committed, " bytes committed (resume there)"));
  if (offset + static_cast<int64_t>(bytes) > digest.size_bytes)
    return absl::InvalidArgumentError(absl::StrCat("blob ", digest.ToString(), ": ",
                                                   offset + static_cast<int64_t>(bytes),
                                                   " bytes sent, more than the digest's size"));
  return absl::OkStatus();
}

absl::Status CheckTenantName(absl::string_view tenant) {
  bool ok = !tenant.empty() && tenant.size() <= 32 && tenant[0] != '-';
  for (char c : tenant) ok &= (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-';
  if (!ok) return absl::InvalidArgumentError("tenant: 1-32 of a-z, 0-9 and '-'");
  return absl::OkStatus();
}

absl::Status BlobStore::PutFile(const Digest& digest, const std::string& path,
                                const TransferProgress& progress) {
  RETURN_IF_ERROR(ValidateDigest(digest));
  ASSIGN_OR_RETURN(int64_t committed, CommittedSize(digest));
  if (committed == digest.size_bytes) {
    ASSIGN_OR_RETURN(std::vector<Digest> missing, FindMissing({digest}));
    if (missing.empty()) {
      if (progress) progress(digest.size_bytes, digest.size_bytes);
      return absl::OkStatus();
    }
  }
  if (digest.size_bytes <= options().max_batch_bytes && committed == 0) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    RETURN_IF_ERROR(Put(digest, bytes));
    if (progress) progress(digest.size_bytes, digest.size_bytes);
    return absl::OkStatus();
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  in.seekg(committed);
  std::vector<char> chunk(1 << 20);
  while (committed < digest.size_bytes) {
    const int64_t want =
        std::min<int64_t>(static_cast<int64_t>(chunk.size()), digest.size_bytes - committed);
    in.read(chunk.data(), want);
    if (in.gcount() != want)
      return absl::DataLossError(
          absl::StrCat(path, ": shorter than its digest says (", digest.size_bytes, " bytes)"));
    ASSIGN_OR_RETURN(committed, Append(digest, committed,
                                       absl::string_view(chunk.data(), static_cast<size_t>(want))));
    if (progress) progress(committed, digest.size_bytes);
  }
  return FinishUpload(digest);
}

absl::Status BlobStore::GetFile(const Digest& digest, const std::string& path) {
  const std::string temp = absl::StrCat(path, ".partial");
  {
    std::ofstream out(temp, std::ios::binary | std::ios::trunc);
    if (!out) return absl::UnavailableError(absl::StrCat(temp, ": cannot create"));
    Sha256 sha;
    constexpr int64_t kChunk = int64_t{4} << 20;
    for (int64_t offset = 0; offset < digest.size_bytes; offset += kChunk) {
      ASSIGN_OR_RETURN(std::string bytes, Read(digest, offset, kChunk));
      sha.Update(bytes);
      out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    }
    if (!out) return absl::UnavailableError(absl::StrCat(temp, ": write failed"));
    if (const std::string hash = sha.HexDigest(); hash != digest.hash) {
      out.close();
      std::remove(temp.c_str());
      return absl::DataLossError(
          absl::StrCat("blob ", digest.ToString(), " read back with hash ", hash));
    }
  }
  RETURN_IF_ERROR(SyncPath(temp, /*directory=*/false));
  return RenameDurably(temp, path);
}

namespace {
absl::Status NoTenants() { return absl::UnimplementedError("this store keeps no tenant grants"); }
}  // namespace

absl::Status BlobStore::Grant(const std::string&, const std::vector<Digest>&) {
  return NoTenants();
}
absl::StatusOr<std::vector<Digest>> BlobStore::FindUngranted(const std::string&,
                                                             const std::vector<Digest>&) {
  return NoTenants();
}
absl::StatusOr<int64_t> BlobStore::TenantCommittedSize(const std::string&, const Digest&) {
  return NoTenants();
}
absl::StatusOr<int64_t> BlobStore::TenantAppend(const std::string&, const Digest&, int64_t,
                                                absl::string_view) {
  return NoTenants();
}
absl::Status BlobStore::TenantFinishUpload(const std::string&, const Digest&) {
  return NoTenants();
}
absl::StatusOr<int64_t> BlobStore::TenantBytes(const std::string&) { return NoTenants(); }

absl::StatusOr<int64_t> GrantNameBytes(absl::string_view name) {
  const size_t dash = name.rfind('-');
  int64_t size = 0;
  if (dash == absl::string_view::npos || !absl::SimpleAtoi(name.substr(dash + 1), &size) ||
      size < 0)
    return absl::DataLossError(absl::StrCat("grant '", name, "' does not end in -SIZE"));
  return size;
}

bool GrantOrder(const StoredGrant& a, const StoredGrant& b) {
  return std::tie(a.tenant, a.digest.hash) < std::tie(b.tenant, b.digest.hash);
}

std::optional<Digest> GrantNameDigest(absl::string_view name) {
  const size_t dash = name.rfind('-');
  if (dash == absl::string_view::npos) return std::nullopt;
  Digest d;
  d.hash = std::string(name.substr(0, dash));
  if (!absl::SimpleAtoi(name.substr(dash + 1), &d.size_bytes) || !ValidateDigest(d).ok())
    return std::nullopt;
  return d;
}

namespace {
absl::Status NoCollection() {
  return absl::UnimplementedError(
      "this store cannot be garbage-collected from here (collect the storage itself: file: or "
      "s3://)");
}
}  // namespace

absl::StatusOr<std::vector<StoredBlob>> BlobStore::ListBlobs() { return NoCollection(); }
absl::StatusOr<std::optional<std::chrono::system_clock::time_point>> BlobStore::BlobModified(
    const Digest&) {
  return NoCollection();
}
absl::Status BlobStore::Remove(const Digest&) { return NoCollection(); }
absl::StatusOr<std::vector<StoredGrant>> BlobStore::ListGrants() { return NoCollection(); }
absl::Status BlobStore::RemoveGrant(const std::string&, const Digest&) { return NoCollection(); }

}  // namespace instascene::store
