#include "services/training/training_service.h"

namespace instascene::training {

grpc::Status TrainingService::GetWorkerStatus(grpc::ServerContext*,
                                              const v1::GetWorkerStatusRequest*,
                                              v1::WorkerStatus* response) {
  worker::FillWorkerStatus(worker_, {"train", "segment"}, response);
  return grpc::Status::OK;
}

}  // namespace instascene::training
