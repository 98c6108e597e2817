#include "services/decomposition/decomposition_service.h"

namespace instascene::decomposition {

grpc::Status DecompositionService::GetWorkerStatus(grpc::ServerContext*,
                                                   const v1::GetWorkerStatusRequest*,
                                                   v1::WorkerStatus* response) {
  worker::FillWorkerStatus(worker_, {"decompose"}, response);
  return grpc::Status::OK;
}

}  // namespace instascene::decomposition
