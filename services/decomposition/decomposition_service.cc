#include "services/decomposition/decomposition_service.h"

namespace instascene::decomposition {

grpc::Status DecompositionService::GetWorkerStatus(grpc::ServerContext*,
                                                   const v1::GetWorkerStatusRequest*,
                                                   v1::WorkerStatus* response) {
  response->add_kinds("decompose");
  response->set_worker_id(worker_->worker_id());
  response->set_current_job_id(worker_->current_job());
  response->set_jobs_succeeded(worker_->succeeded());
  response->set_jobs_failed(worker_->failed());
  response->set_state(worker_->draining() ? "draining" : "serving");
  return grpc::Status::OK;
}

}  // namespace instascene::decomposition
