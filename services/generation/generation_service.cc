#include "services/generation/generation_service.h"

namespace instascene::generation {

grpc::Status GenerationService::GetWorkerStatus(grpc::ServerContext* context,
                                                const v1::GetWorkerStatusRequest*,
                                                v1::WorkerStatus* response) {
  return worker::AnswerWorkerStatus(auth_, context, worker_, {"complete"}, response);
}

}  // namespace instascene::generation
