// common/store/blob_store_uri.h: opens a blob store named by a URI, the form every binary's
// --store flag takes for the storage itself:
//   file:DIR                               the filesystem store (embedded default: DATA/store)
//   s3://BUCKET[/PREFIX][?endpoint=URL&region=R&addressing=path|virtual]
//                                          an S3-compatible object store (s3_client.h; credentials
//                                          from the environment or ~/.aws/credentials only)
// (A bare HOST:PORT is the store *service*; services/store's RemoteBlobStore opens that.)
#pragma once

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "common/store/blob_store.h"

namespace instascene::store {

// Whether `spec` names storage (file: or s3://) rather than a store service address.
bool IsBlobStoreUri(const std::string& spec);

absl::StatusOr<std::unique_ptr<BlobStore>> OpenBlobStoreUri(const std::string& uri,
                                                            const StoreOptions& options);

}  // namespace instascene::store
