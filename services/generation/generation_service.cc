#include "services/generation/generation_service.h"

namespace instascene::generation {

grpc::Status GenerationService::GetWorkerStatus(grpc::ServerContext*,
                                                const v1::GetWorkerStatusRequest*,
                                                v1::WorkerStatus* response) {
  worker::FillWorkerStatus(worker_, {"complete"}, response);
  return grpc::Status::OK;
}

}  // namespace instascene::generation
