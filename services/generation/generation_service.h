// services/generation/generation_service.h: the Generation gRPC service (generation.proto). The
// work arrives through the scheduler (a StageWorker leasing "complete" jobs); this adapter answers
// monitoring. Thread-safe.
#pragma once

#include "instascene/v1/generation.grpc.pb.h"
#include "services/worker/stage_worker.h"

namespace instascene::generation {

class GenerationService final : public v1::Generation::Service {
 public:
  explicit GenerationService(const worker::StageWorker* worker) : worker_(worker) {}
  grpc::Status GetWorkerStatus(grpc::ServerContext*, const v1::GetWorkerStatusRequest*,
                               v1::WorkerStatus* response) override;

 private:
  const worker::StageWorker* worker_;  // not owned
};

}  // namespace instascene::generation
