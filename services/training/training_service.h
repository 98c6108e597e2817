// services/training/training_service.h: the Training gRPC service (training.proto): the status of
// the worker leasing train and segment jobs. (Lookups on finished results are the Objects
// service's: services/objects/objects_service.h.)
#pragma once

#include "instascene/v1/training.grpc.pb.h"
#include "services/worker/stage_worker.h"

namespace instascene::training {

class TrainingService final : public v1::Training::Service {
 public:
  explicit TrainingService(const worker::StageWorker* worker) : worker_(worker) {}

  grpc::Status GetWorkerStatus(grpc::ServerContext*, const v1::GetWorkerStatusRequest*,
                               v1::WorkerStatus* response) override;

 private:
  const worker::StageWorker* worker_;
};

}  // namespace instascene::training
