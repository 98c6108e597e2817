// services/generation/generation_service.h: the Generation gRPC service (generation.proto). The
// work arrives through the scheduler (a StageWorker leasing "complete" jobs); this adapter answers
// monitoring. Thread-safe.
#pragma once

#include "instascene/v1/generation.grpc.pb.h"
#include "services/worker/stage_worker.h"

namespace instascene::generation {

class GenerationService final : public v1::Generation::Service {
 public:
  // auth null = authentication off. Both must outlive the service.
  explicit GenerationService(const worker::StageWorker* worker, auth::Authenticator* auth = nullptr)
      : worker_(worker), auth_(auth) {}
  grpc::Status GetWorkerStatus(grpc::ServerContext*, const v1::GetWorkerStatusRequest*,
                               v1::WorkerStatus* response) override;

 private:
  const worker::StageWorker* worker_;  // not owned
  auth::Authenticator* auth_;
};

}  // namespace instascene::generation
