// services/store/store_service.h: the ContentStore gRPC service (store.proto), a thin adapter over
// a BlobStore. Statuses: INVALID_ARGUMENT malformed digest or digest mismatch (nothing stored),
// RESOURCE_EXHAUSTED blob or batch over the limits or a tenant's upload over its quota
// (tenant_quota.h), NOT_FOUND unknown digest, FAILED_PRECONDITION
// write at the wrong offset (the message names the committed size to resume at), OUT_OF_RANGE bad
// read range. Every call is authorized first (common/auth): clients see their tenant's blobs only
// (store.proto says how), workers and admins the whole store; UNAUTHENTICATED without a valid
// token, PERMISSION_DENIED for a role a method does not allow. Thread-safe (the BlobStore is).
#pragma once

#include "common/auth/authenticator.h"
#include "common/store/blob_store.h"
#include "instascene/v1/store.grpc.pb.h"
#include "services/store/tenant_quota.h"

namespace instascene::store_service {

class StoreService final : public v1::ContentStore::Service {
 public:
  // `auth` null = authentication off (every caller unrestricted). Both must outlive the service.
  explicit StoreService(store::BlobStore* store, auth::Authenticator* auth = nullptr)
      : store_(store), auth_(auth), quota_(store) {}

  grpc::Status FindMissingBlobs(grpc::ServerContext*, const v1::FindMissingBlobsRequest* request,
                                v1::FindMissingBlobsResponse* response) override;
  grpc::Status BatchUpdateBlobs(grpc::ServerContext*, const v1::BatchUpdateBlobsRequest* request,
                                v1::BatchUpdateBlobsResponse* response) override;
  grpc::Status BatchReadBlobs(grpc::ServerContext*, const v1::BatchReadBlobsRequest* request,
                              v1::BatchReadBlobsResponse* response) override;
  grpc::Status Write(grpc::ServerContext*, grpc::ServerReader<v1::WriteRequest>* reader,
                     v1::WriteResponse* response) override;
  grpc::Status QueryWriteStatus(grpc::ServerContext*, const v1::QueryWriteStatusRequest* request,
                                v1::QueryWriteStatusResponse* response) override;
  grpc::Status Read(grpc::ServerContext*, const v1::ReadRequest* request,
                    grpc::ServerWriter<v1::ReadResponse>* writer) override;
  grpc::Status GetStoreInfo(grpc::ServerContext*, const v1::GetStoreInfoRequest*,
                            v1::GetStoreInfoResponse* response) override;
  grpc::Status GrantBlobs(grpc::ServerContext*, const v1::GrantBlobsRequest* request,
                          v1::GrantBlobsResponse* response) override;
  grpc::Status FindUngrantedBlobs(grpc::ServerContext*,
                                  const v1::FindUngrantedBlobsRequest* request,
                                  v1::FindUngrantedBlobsResponse* response) override;

 private:
  absl::StatusOr<auth::Identity> Caller(grpc::ServerContext* context) const;
  // NotFound for a blob the caller may not read (the same answer as for a blob nobody stored).
  absl::Status CheckReadable(const auth::Identity& who, const store::Digest& digest) const;

  // A tenant's upload within its quota (OK for unscoped callers and blobs it holds already).
  absl::Status AdmitNew(const auth::Identity& who, const store::Digest& digest);

  store::BlobStore* store_;    // not owned
  auth::Authenticator* auth_;  // not owned; null = off
  TenantQuota quota_;
};

}  // namespace instascene::store_service
