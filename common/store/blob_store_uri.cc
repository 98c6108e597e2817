#include "common/store/blob_store_uri.h"

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/store/s3_blob_store.h"

namespace instascene::store {

bool IsBlobStoreUri(const std::string& spec) {
  return absl::StartsWith(spec, "file:") || absl::StartsWith(spec, "s3://");
}

absl::StatusOr<std::unique_ptr<BlobStore>> OpenBlobStoreUri(const std::string& uri,
                                                            const StoreOptions& options) {
  if (absl::StartsWith(uri, "file:")) {
    const std::string dir = uri.substr(5);
    if (dir.empty()) return absl::InvalidArgumentError("--store file: needs a directory");
    ASSIGN_OR_RETURN(std::unique_ptr<FilesystemBlobStore> fs,
                     FilesystemBlobStore::Open(dir, options));
    return std::unique_ptr<BlobStore>(std::move(fs));
  }
  if (absl::StartsWith(uri, "s3://")) {
    ASSIGN_OR_RETURN(S3Location location, S3Location::Parse(uri));
    ASSIGN_OR_RETURN(S3Credentials credentials, S3Credentials::Load());
    ASSIGN_OR_RETURN(std::unique_ptr<S3BlobStore> s3,
                     S3BlobStore::Open(location, credentials, options));
    return std::unique_ptr<BlobStore>(std::move(s3));
  }
  return absl::InvalidArgumentError(
      absl::StrCat("--store: expected file:DIR or s3://BUCKET/PREFIX?endpoint=..., not '",
                   uri.substr(0, 80), "'"));
}

}  // namespace instascene::store
