// services/worker/lease_heartbeat.h: what a worker does while its stage runs. ProgressTracker
// keeps the stage's latest progress with an ETA from the rate within the current phase;
// LeaseHeartbeat renews the job's lease with that progress on its own thread and raises the
// stage's cancel flag when the scheduler asks to cancel or no longer knows the lease.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <string>
#include <thread>

#include "common/core/cancel.h"
#include "common/core/timer.h"
#include "instascene/v1/scheduler.grpc.pb.h"
#include "services/pipeline/registry.h"

namespace instascene::worker {

// Latest progress of the running stage with an ETA from the rate within the current phase.
class ProgressTracker {
 public:
  void Update(const pipeline::StageProgress& p);
  v1::Progress Get() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return current_;
  }

 private:
  mutable std::mutex mutex_;
  v1::Progress current_;
  Stopwatch phase_watch_;
};

// Renews a running job's lease every `interval` with the stage's progress, on its own thread from
// construction until Stop() or destruction. A lease the scheduler no longer knows
// (FAILED_PRECONDITION, NOT_FOUND) and a cancellation request both set `cancel`, which the stage
// polls. Stop() waits for a heartbeat in flight (its deadline is 10 s).
class LeaseHeartbeat {
 public:
  LeaseHeartbeat(v1::Scheduler::Stub* scheduler, const v1::LeaseJobResponse& lease,
                 std::chrono::milliseconds interval, const std::string& worker_id,
                 const ProgressTracker& progress, CancelFlag* cancel)
      : thread_([this, scheduler, &lease, interval, worker_id, &progress, cancel] {
          Run(scheduler, lease, interval, worker_id, progress, cancel);
        }) {}
  ~LeaseHeartbeat() { Stop(); }
  LeaseHeartbeat(const LeaseHeartbeat&) = delete;
  LeaseHeartbeat& operator=(const LeaseHeartbeat&) = delete;

  void Stop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
  }
  bool lease_lost() const { return lease_lost_; }
  bool cancel_requested() const { return cancel_requested_; }

 private:
  void Run(v1::Scheduler::Stub* scheduler, const v1::LeaseJobResponse& lease,
           std::chrono::milliseconds interval, const std::string& worker_id,
           const ProgressTracker& progress, CancelFlag* cancel);

  std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;  // under mutex_
  std::atomic<bool> lease_lost_{false}, cancel_requested_{false};
  std::thread thread_;  // last: starts once every other member is constructed
};

}  // namespace instascene::worker
