// services/training/training_service.h: the Training gRPC service (training.proto): worker status,
// and click / 3D-point queries answered directly from a finished result. Query indexes are built
// once per (scene, result) pair and kept in a small LRU cache, so repeated clicks are lookups.
// Thread-safe.
#pragma once

#include <list>
#include <memory>
#include <mutex>

#include "common/store/blob_store.h"
#include "instascene/v1/training.grpc.pb.h"
#include "services/training/query.h"
#include "services/worker/stage_worker.h"

namespace instascene::training {

class TrainingService final : public v1::Training::Service {
 public:
  // worker may be null (query-only); store must outlive the service.
  TrainingService(store::BlobStore* store, std::string work_dir, const worker::StageWorker* worker,
                  int cache_entries = 4);

  grpc::Status GetWorkerStatus(grpc::ServerContext*, const v1::GetWorkerStatusRequest*,
                               v1::WorkerStatus* response) override;
  grpc::Status Query(grpc::ServerContext*, const v1::QueryRequest* request,
                     v1::QueryResponse* response) override;

 private:
  struct Loaded {
    std::string key;
    Scene scene;
    GaussianCloud cloud;
    std::unique_ptr<QueryIndex> index;
    float point_radius = 0;  // 3D queries: 2 % of the scene's robust diagonal
  };
  absl::StatusOr<std::shared_ptr<Loaded>> Load(const store::Digest& scene,
                                               const store::Digest& result);
  absl::Status Answer(const v1::QueryRequest& request, v1::QueryResponse* response);

  store::BlobStore* store_;
  std::string work_dir_;
  const worker::StageWorker* worker_;
  size_t cache_entries_;
  std::mutex mutex_;                          // guards cache_ and serialises index builds
  std::list<std::shared_ptr<Loaded>> cache_;  // most recent first
};

}  // namespace instascene::training
