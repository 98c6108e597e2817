// services/store/store_service.h: the ContentStore gRPC service (store.proto), a thin adapter over
// a BlobStore. Statuses: INVALID_ARGUMENT malformed digest or digest mismatch (nothing stored),
// RESOURCE_EXHAUSTED blob or batch over the limits, NOT_FOUND unknown digest, FAILED_PRECONDITION
// write at the wrong offset (the message names the committed size to resume at), OUT_OF_RANGE bad
// read range. Thread-safe (the BlobStore is).
#pragma once

#include "common/store/blob_store.h"
#include "instascene/v1/store.grpc.pb.h"

namespace instascene::store_service {

class StoreService final : public v1::ContentStore::Service {
 public:
  explicit StoreService(store::BlobStore* store) : store_(store) {}

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

 private:
  store::BlobStore* store_;  // not owned
};

}  // namespace instascene::store_service
