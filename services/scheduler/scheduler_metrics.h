// services/scheduler/scheduler_metrics.h: the scheduler's Prometheus metrics (issue 16).
// Events, counted as they happen (SchedulerService calls these):
//   instascene_job_queue_wait_seconds{stage}        histogram: creation (or the retry's backoff
//                                                   end) to lease
//   instascene_job_leases_total{stage}              counter: attempts started
//   instascene_jobs_finished_total{stage, outcome}  counter: succeeded | failed | retried |
//                                                   cancelled
//   instascene_rescued_leases_total                 counter: expired leases handed back
// State, read from the queue's storage at scrape time (QueueCollector):
//   instascene_jobs{stage, state}                   gauge: jobs per stage and state
//   instascene_queue_oldest_queued_age_seconds{stage} gauge
//   instascene_scenes                               gauge
// Thread-safe.
#pragma once

#include <memory>
#include <string>

#include <prometheus/collectable.h>

namespace instascene::scheduler {

class JobQueue;

void RecordLease(const std::string& stage, double queue_wait_seconds);
void RecordFinished(const std::string& stage, const std::string& outcome);
void RecordRescued(int leases);

// Reads JobQueue::Stats() on every scrape; `queue` must outlive the collectable.
std::shared_ptr<prometheus::Collectable> QueueCollector(JobQueue* queue);

}  // namespace instascene::scheduler
