// services/store/remote_blob_store.h: a BlobStore that talks to a ContentStore service over gRPC,
// so workers and clients use the same manifest / upload / download code against a remote store as
// against a local one. Small blobs go in batch RPCs, large ones in resumable Write streams (PutFile
// asks QueryWriteStatus for the committed size and continues there). Thread-safe.
#pragma once

#include <grpcpp/grpcpp.h>

#include "common/store/blob_store.h"
#include "instascene/v1/store.grpc.pb.h"

namespace instascene::store_service {

class RemoteBlobStore final : public store::BlobStore {
 public:
  // Fetches the server's limits (GetStoreInfo); fails if the server cannot be reached.
  static absl::StatusOr<std::unique_ptr<RemoteBlobStore>> Connect(
      std::shared_ptr<grpc::Channel> channel, int timeout_ms = 10000);

  const store::StoreOptions& options() const override { return options_; }
  absl::StatusOr<std::vector<store::Digest>> FindMissing(
      const std::vector<store::Digest>& digests) override;
  absl::Status Put(const store::Digest& digest, absl::string_view bytes) override;
  absl::StatusOr<std::string> Read(const store::Digest& digest, int64_t offset = 0,
                                   int64_t limit = 0) override;
  absl::StatusOr<int64_t> CommittedSize(const store::Digest& digest) override;
  absl::StatusOr<int64_t> Append(const store::Digest& digest, int64_t offset,
                                 absl::string_view data) override;
  absl::Status FinishUpload(const store::Digest& digest) override;
  absl::StatusOr<store::StoreStats> Stats() override;
  // Through GrantBlobs / FindUngrantedBlobs (a worker or admin token). Tenant uploads are the
  // store service's own business: a client's uploads are already tenant uploads there.
  absl::Status Grant(const std::string& tenant, const std::vector<store::Digest>& digests) override;
  absl::StatusOr<std::vector<store::Digest>> FindUngranted(
      const std::string& tenant, const std::vector<store::Digest>& digests) override;
  absl::Status PutFile(const store::Digest& digest, const std::string& path,
                       const store::TransferProgress& progress = nullptr) override;

 private:
  explicit RemoteBlobStore(std::unique_ptr<v1::ContentStore::Stub> stub) : stub_(std::move(stub)) {}
  absl::Status CheckSize(const store::Digest& digest) const;
  // One Write stream: `chunks` yields (data) until empty; starts at `offset`.
  absl::StatusOr<int64_t> WriteStream(const store::Digest& digest, int64_t offset,
                                      const std::function<absl::StatusOr<std::string>()>& next,
                                      bool finish, const store::TransferProgress& progress);

  std::unique_ptr<v1::ContentStore::Stub> stub_;
  store::StoreOptions options_;
};

}  // namespace instascene::store_service
