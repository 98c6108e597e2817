#include "services/decomposition/decomposition_service.h"

namespace instascene::decomposition {

grpc::Status DecompositionService::GetWorkerStatus(grpc::ServerContext* context,
                                                   const v1::GetWorkerStatusRequest*,
                                                   v1::WorkerStatus* response) {
  return worker::AnswerWorkerStatus(auth_, context, worker_, {"decompose"}, response);
}

}  // namespace instascene::decomposition
