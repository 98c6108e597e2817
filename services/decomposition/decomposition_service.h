// services/decomposition/decomposition_service.h: the Decomposition gRPC service
// (decomposition.proto). The work itself arrives through the scheduler (a StageWorker leasing
// "decompose" jobs); this adapter answers monitoring. Thread-safe.
#pragma once

#include "instascene/v1/decomposition.grpc.pb.h"
#include "services/worker/stage_worker.h"

namespace instascene::decomposition {

class DecompositionService final : public v1::Decomposition::Service {
 public:
  // auth null = authentication off. Both must outlive the service.
  explicit DecompositionService(const worker::StageWorker* worker,
                                auth::Authenticator* auth = nullptr)
      : worker_(worker), auth_(auth) {}
  grpc::Status GetWorkerStatus(grpc::ServerContext*, const v1::GetWorkerStatusRequest*,
                               v1::WorkerStatus* response) override;

 private:
  const worker::StageWorker* worker_;  // not owned
  auth::Authenticator* auth_;
};

}  // namespace instascene::decomposition
