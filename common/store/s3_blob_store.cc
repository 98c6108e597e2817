#include "common/store/s3_blob_store.h"

#include <algorithm>
#include <atomic>
#include <thread>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene::store {
namespace {

constexpr int64_t kMiB = int64_t{1} << 20;
constexpr int64_t kMaxSinglePut = int64_t{5} << 30;  // S3's limit of one PUT (and of a part)
constexpr size_t kFindMissingConcurrency = 16;

}  // namespace

absl::Status S3StoreOptions::Validate() const {
  if (part_bytes < 5 * kMiB || part_bytes > kMaxSinglePut)
    return absl::InvalidArgumentError("S3 part size must be in [5 MiB, 5 GiB]");
  if (copy_part_bytes < 5 * kMiB || copy_part_bytes > kMaxSinglePut)
    return absl::InvalidArgumentError("S3 copy part size must be in [5 MiB, 5 GiB]");
  if (verify_chunk_bytes < 1) return absl::InvalidArgumentError("verify chunk must be positive");
  if (max_buffered_uploads < 1)
    return absl::InvalidArgumentError("max_buffered_uploads must be >= 1");
  if (touch_after_seconds < 0)
    return absl::InvalidArgumentError("touch_after_seconds must be >= 0");
  return absl::OkStatus();
}

int64_t S3BlobStore::Upload::durable() const {
  int64_t total = 0;
  for (const S3Client::Part& p : parts) total += p.size;
  return total;
}

absl::StatusOr<std::unique_ptr<S3BlobStore>> S3BlobStore::Open(
    const S3Location& location, const S3Credentials& credentials, const StoreOptions& options,
    const S3StoreOptions& s3_options, const S3ClientOptions& client_options) {
  RETURN_IF_ERROR(options.Validate());
  RETURN_IF_ERROR(s3_options.Validate());
  auto client = std::make_unique<S3Client>(location, credentials, client_options);
  RETURN_IF_ERROR(client->HeadBucket());
  return std::unique_ptr<S3BlobStore>(new S3BlobStore(std::move(client), options, s3_options));
}

std::string S3BlobStore::BlobKey(const Digest& digest) const {
  return absl::StrCat(client_->location().prefix, "cas/", digest.hash);
}

std::string S3BlobStore::UploadKey(const Digest& digest, const std::string& space) const {
  return absl::StrCat(client_->location().prefix, "uploads/", space, space.empty() ? "" : "/",
                      digest.hash, "-", digest.size_bytes);
}

std::string S3BlobStore::GrantKey(const std::string& tenant, const Digest& digest) const {
  return absl::StrCat(client_->location().prefix, "grants/", tenant, "/", digest.hash, "-",
                      digest.size_bytes);
}

absl::StatusOr<std::vector<Digest>> S3BlobStore::FindMissing(const std::vector<Digest>& digests) {
  for (const Digest& d : digests) RETURN_IF_ERROR(ValidateDigest(d));
  // One HEAD per digest, kFindMissingConcurrency in flight (network-bound: a scene upload asks for
  // hundreds); the answer keeps the request's order.
  std::vector<char> present(digests.size(), 0);
  std::vector<absl::Status> errors(digests.size());
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t i; (i = next.fetch_add(1)) < digests.size();) {
      absl::StatusOr<bool> found = Contains(digests[i]);
      if (found.ok())
        present[i] = *found;
      else
        errors[i] = found.status();
    }
  };
  const size_t threads = std::min(kFindMissingConcurrency, digests.size());
  std::vector<std::thread> pool;
  for (size_t t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  std::vector<Digest> missing;
  for (size_t i = 0; i < digests.size(); ++i) {
    RETURN_IF_ERROR(errors[i]);
    if (!present[i]) missing.push_back(digests[i]);
  }
  return missing;
}

absl::Status S3BlobStore::Put(const Digest& digest, absl::string_view bytes) {
  RETURN_IF_ERROR(CheckWritable(digest, options_));
  RETURN_IF_ERROR(VerifyBlobBytes(digest, bytes));
  ASSIGN_OR_RETURN(bool present, Contains(digest));
  if (present) return absl::OkStatus();
  if (digest.size_bytes <= kMaxSinglePut) return client_->PutObject(BlobKey(digest), bytes);
  int64_t offset = 0;  // beyond one PUT: the resumable path
  while (offset < digest.size_bytes) {
    const int64_t n = std::min(s3_options_.part_bytes, digest.size_bytes - offset);
    ASSIGN_OR_RETURN(offset, Append(digest, offset, bytes.substr(offset, n)));
  }
  return FinishUpload(digest);
}

absl::StatusOr<std::string> S3BlobStore::Read(const Digest& digest, int64_t offset, int64_t limit) {
  RETURN_IF_ERROR(ValidateDigest(digest));
  if (offset < 0 || limit < 0 || offset > digest.size_bytes)
    return absl::OutOfRangeError(absl::StrCat("blob ", digest.ToString(), ": read offset ", offset,
                                              " / limit ", limit, " out of range"));
  int64_t count = digest.size_bytes - offset;
  if (limit > 0) count = std::min(count, limit);
  const absl::Status not_found =
      absl::NotFoundError(absl::StrCat("blob ", digest.ToString(), " is not in the store"));
  if (count == 0) {
    ASSIGN_OR_RETURN(bool present, Contains(digest));
    if (!present) return not_found;
    return std::string();
  }
  absl::StatusOr<std::string> bytes = client_->GetObject(BlobKey(digest), offset, count);
  if (absl::IsNotFound(bytes.status())) return not_found;
  if (!bytes.ok()) return bytes.status();
  if (static_cast<int64_t>(bytes->size()) != count)
    return absl::DataLossError(absl::StrCat("blob ", digest.ToString(), ": S3 returned ",
                                            bytes->size(), " bytes of ", count, " asked"));
  if (options_.verify_reads && offset == 0 && count == digest.size_bytes &&
      ComputeDigest(*bytes).hash != digest.hash)
    return absl::DataLossError(absl::StrCat("blob ", digest.ToString(), " is corrupt in S3"));
  return bytes;
}

absl::Status S3BlobStore::Grant(const std::string& tenant, const std::vector<Digest>& digests) {
  RETURN_IF_ERROR(CheckTenantName(tenant));
  for (const Digest& d : digests) {
    RETURN_IF_ERROR(ValidateDigest(d));
    ASSIGN_OR_RETURN(bool present, Contains(d));
    if (!present)
      return absl::FailedPreconditionError(
          absl::StrCat("blob ", d.ToString(), " is not in the store: nothing to grant"));
    RETURN_IF_ERROR(client_->PutObject(GrantKey(tenant, d), ""));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::vector<Digest>> S3BlobStore::FindUngranted(const std::string& tenant,
                                                               const std::vector<Digest>& digests) {
  RETURN_IF_ERROR(CheckTenantName(tenant));
  std::vector<Digest> out;
  for (const Digest& d : digests) {
    RETURN_IF_ERROR(ValidateDigest(d));
    ASSIGN_OR_RETURN(std::optional<int64_t> grant, client_->HeadObject(GrantKey(tenant, d)));
    bool granted = grant.has_value();
    if (granted) {
      ASSIGN_OR_RETURN(granted, Contains(d));
    }
    if (!granted) out.push_back(d);
  }
  return out;
}

absl::StatusOr<int64_t> S3BlobStore::TenantCommittedSize(const std::string& tenant,
                                                         const Digest& digest) {
  ASSIGN_OR_RETURN(std::vector<Digest> ungranted, FindUngranted(tenant, {digest}));
  if (ungranted.empty()) return digest.size_bytes;
  return PartSize(digest, tenant);
}

absl::StatusOr<int64_t> S3BlobStore::TenantAppend(const std::string& tenant, const Digest& digest,
                                                  int64_t offset, absl::string_view data) {
  RETURN_IF_ERROR(CheckTenantName(tenant));
  if (offset == 0) {  // a new upload of a blob already the tenant's stages nothing
    ASSIGN_OR_RETURN(std::vector<Digest> ungranted, FindUngranted(tenant, {digest}));
    if (ungranted.empty()) return digest.size_bytes;
  }
  return AppendPart(digest, tenant, offset, data);
}

absl::Status S3BlobStore::TenantFinishUpload(const std::string& tenant, const Digest& digest) {
  ASSIGN_OR_RETURN(std::vector<Digest> ungranted, FindUngranted(tenant, {digest}));
  if (ungranted.empty()) return absl::OkStatus();
  RETURN_IF_ERROR(CheckWritable(digest, options_));
  RETURN_IF_ERROR(FinishPart(digest, tenant));
  return Grant(tenant, {digest});
}

absl::StatusOr<StoreStats> S3BlobStore::Stats() {
  ASSIGN_OR_RETURN(std::vector<S3Client::Object> objects,
                   client_->ListObjects(absl::StrCat(client_->location().prefix, "cas/")));
  StoreStats stats;
  for (const S3Client::Object& o : objects) {
    ++stats.blob_count;
    stats.total_bytes += o.size;
  }
  return stats;
}

}  // namespace instascene::store
