#include "services/training/training_service.h"

namespace instascene::training {

grpc::Status TrainingService::GetWorkerStatus(grpc::ServerContext* context,
                                              const v1::GetWorkerStatusRequest*,
                                              v1::WorkerStatus* response) {
  return worker::AnswerWorkerStatus(auth_, context, worker_, {"train", "segment"}, response);
}

}  // namespace instascene::training
