// S3BlobStore's side of garbage collection and tenants' usage (s3_blob_store.h): presence checks
// that keep a blob about to be referenced young, the listings of `cas/` and `grants/` with
// modification times, removal of a blob and of a grant, and the bytes granted to a tenant.
#include <algorithm>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/store/s3_blob_store.h"

namespace instascene::store {

absl::StatusOr<bool> S3BlobStore::Contains(const Digest& digest) {
  ASSIGN_OR_RETURN(std::optional<S3Client::ObjectInfo> info, client_->StatObject(BlobKey(digest)));
  if (!info.has_value() || info->size != digest.size_bytes) return false;
  if (std::chrono::system_clock::now() - info->modified >
      std::chrono::seconds(s3_options_.touch_after_seconds)) {
    // A failed touch fails the call: a collector could otherwise remove what the caller is about
    // to reference (every caller retries on Unavailable).
    RETURN_IF_ERROR(Touch(digest));
  }
  return true;
}

absl::Status S3BlobStore::Touch(const Digest& digest) {
  // One copy request up to copy_part_bytes (<= 5 GiB, S3's limit of a copy); above, the
  // multipart copy FinishUpload uses, here from the blob onto itself.
  if (digest.size_bytes <= s3_options_.copy_part_bytes)
    return client_->TouchObject(BlobKey(digest));
  return CopyToBlob(BlobKey(digest), digest);
}

absl::StatusOr<std::vector<StoredBlob>> S3BlobStore::ListBlobs() {
  const std::string prefix = absl::StrCat(client_->location().prefix, "cas/");
  ASSIGN_OR_RETURN(std::vector<S3Client::Object> objects, client_->ListObjects(prefix));
  std::vector<StoredBlob> blobs;
  for (const S3Client::Object& o : objects) {
    StoredBlob b;
    b.digest.hash = o.key.substr(prefix.size());
    b.digest.size_bytes = o.size;
    if (!ValidateDigest(b.digest).ok()) continue;  // not a blob (nothing else lives there)
    b.modified = o.modified;
    blobs.push_back(std::move(b));
  }
  std::sort(blobs.begin(), blobs.end(),
            [](const StoredBlob& a, const StoredBlob& b) { return a.digest.hash < b.digest.hash; });
  return blobs;
}

absl::StatusOr<std::optional<std::chrono::system_clock::time_point>> S3BlobStore::BlobModified(
    const Digest& digest) {
  RETURN_IF_ERROR(ValidateDigest(digest));
  ASSIGN_OR_RETURN(std::optional<S3Client::ObjectInfo> info, client_->StatObject(BlobKey(digest)));
  if (!info.has_value()) return std::optional<std::chrono::system_clock::time_point>();
  return std::optional(info->modified);
}

absl::StatusOr<int64_t> S3BlobStore::TenantBytes(const std::string& tenant) {
  RETURN_IF_ERROR(CheckTenantName(tenant));
  const std::string folder = absl::StrCat(client_->location().prefix, "grants/", tenant, "/");
  ASSIGN_OR_RETURN(std::vector<S3Client::Object> grants, client_->ListObjects(folder));
  int64_t total = 0;
  for (const S3Client::Object& g : grants) {
    ASSIGN_OR_RETURN(const int64_t size, GrantNameBytes(g.key.substr(folder.size())));
    total += size;
  }
  return total;
}

absl::Status S3BlobStore::Remove(const Digest& digest) {
  RETURN_IF_ERROR(ValidateDigest(digest));
  return client_->DeleteObject(BlobKey(digest));  // S3 answers 204 for an absent key
}

absl::StatusOr<std::vector<StoredGrant>> S3BlobStore::ListGrants() {
  const std::string prefix = absl::StrCat(client_->location().prefix, "grants/");
  ASSIGN_OR_RETURN(std::vector<S3Client::Object> objects, client_->ListObjects(prefix));
  std::vector<StoredGrant> grants;
  for (const S3Client::Object& o : objects) {
    // grants/<tenant>/<hash>-<size>: anything else there is not a grant.
    const std::string rest = o.key.substr(prefix.size());
    const size_t slash = rest.find('/');
    if (slash == std::string::npos) continue;
    StoredGrant g;
    g.tenant = rest.substr(0, slash);
    std::optional<Digest> digest = GrantNameDigest(rest.substr(slash + 1));
    if (!digest.has_value() || !CheckTenantName(g.tenant).ok()) continue;
    g.digest = std::move(*digest);
    g.modified = o.modified;
    grants.push_back(std::move(g));
  }
  std::sort(grants.begin(), grants.end(), GrantOrder);
  return grants;
}

absl::Status S3BlobStore::RemoveGrant(const std::string& tenant, const Digest& digest) {
  RETURN_IF_ERROR(CheckTenantName(tenant));
  RETURN_IF_ERROR(ValidateDigest(digest));
  return client_->DeleteObject(GrantKey(tenant, digest));
}

}  // namespace instascene::store
