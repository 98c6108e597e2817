#include "services/worker/lease_heartbeat.h"

#include <spdlog/spdlog.h>

namespace instascene::worker {

void ProgressTracker::Update(const pipeline::StageProgress& p) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (p.phase != current_.phase()) {
    phase_watch_ = Stopwatch();
  }
  current_.set_phase(p.phase);
  current_.set_step(p.step);
  current_.set_total(p.total);
  current_.set_loss(p.loss);
  const double elapsed = phase_watch_.ElapsedSeconds();
  current_.set_eta_seconds(p.step > 0 && p.total >= p.step
                               ? elapsed * static_cast<double>(p.total - p.step) / p.step
                               : -1.0);
}

void LeaseHeartbeat::Run(v1::Scheduler::Stub* scheduler, const v1::LeaseJobResponse& lease,
                         std::chrono::milliseconds interval, const std::string& worker_id,
                         const ProgressTracker& progress, CancelFlag* cancel) {
  const v1::Job& job = lease.job();
  std::unique_lock<std::mutex> lock(mutex_);
  while (!wake_.wait_for(lock, interval, [&] { return stop_; })) {
    v1::HeartbeatRequest request;
    request.set_job_id(job.id());
    request.set_lease_token(lease.lease_token());
    *request.mutable_progress() = progress.Get();
    v1::HeartbeatResponse response;
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    const grpc::Status s = scheduler->Heartbeat(&context, request, &response);
    if (s.error_code() == grpc::StatusCode::FAILED_PRECONDITION ||
        s.error_code() == grpc::StatusCode::NOT_FOUND) {
      spdlog::warn("worker {}: job {}: {}; stopping it", worker_id, job.id(), s.error_message());
      lease_lost_ = true;
      *cancel = true;
    } else if (s.ok() && response.cancel_requested()) {
      cancel_requested_ = true;
      *cancel = true;
    }
  }
}

}  // namespace instascene::worker
