// services/training/training_service.h: the Training gRPC service (training.proto): the status of
// the worker leasing train and segment jobs. (Lookups on finished results are the Objects
// service's: services/objects/objects_service.h.)
#pragma once

#include "instascene/v1/training.grpc.pb.h"
#include "services/worker/stage_worker.h"

namespace instascene::training {

class TrainingService final : public v1::Training::Service {
 public:
  // auth null = authentication off. Both must outlive the service.
  explicit TrainingService(const worker::StageWorker* worker, auth::Authenticator* auth = nullptr)
      : worker_(worker), auth_(auth) {}

  grpc::Status GetWorkerStatus(grpc::ServerContext*, const v1::GetWorkerStatusRequest*,
                               v1::WorkerStatus* response) override;

 private:
  const worker::StageWorker* worker_;
  auth::Authenticator* auth_;
};

}  // namespace instascene::training
