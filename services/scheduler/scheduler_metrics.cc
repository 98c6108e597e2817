#include "services/scheduler/scheduler_metrics.h"

#include "common/metrics/metrics.h"
#include "services/scheduler/job_queue.h"

namespace instascene::scheduler {
namespace {

prometheus::Family<prometheus::Histogram>& QueueWait() {
  static auto& f = prometheus::BuildHistogram()
                       .Name("instascene_job_queue_wait_seconds")
                       .Help("Time from a job's creation (or its retry's backoff end) to its lease")
                       .Register(metrics::Registry());
  return f;
}

prometheus::Family<prometheus::Counter>& Leases() {
  static auto& f = prometheus::BuildCounter()
                       .Name("instascene_job_leases_total")
                       .Help("Job attempts started (leases granted), by stage")
                       .Register(metrics::Registry());
  return f;
}

prometheus::Family<prometheus::Counter>& Finished() {
  static auto& f =
      prometheus::BuildCounter()
          .Name("instascene_jobs_finished_total")
          .Help("Job attempts ended, by stage and outcome (succeeded, failed, retried, cancelled)")
          .Register(metrics::Registry());
  return f;
}

prometheus::Counter& Rescued() {
  static auto& c = prometheus::BuildCounter()
                       .Name("instascene_rescued_leases_total")
                       .Help("Expired leases handed back to the queue (or ended) by the scheduler")
                       .Register(metrics::Registry())
                       .Add({});
  return c;
}

}  // namespace

void RecordLease(const std::string& stage, double queue_wait_seconds) {
  QueueWait().Add({{"stage", stage}}, metrics::JobBuckets()).Observe(queue_wait_seconds);
  Leases().Add({{"stage", stage}}).Increment();
}

void RecordFinished(const std::string& stage, const std::string& outcome) {
  Finished().Add({{"stage", stage}, {"outcome", outcome}}).Increment();
}

void RecordRescued(int leases) {
  if (leases > 0) Rescued().Increment(leases);
}

std::shared_ptr<prometheus::Collectable> QueueCollector(JobQueue* queue) {
  // Registered up front so that a scrape shows them at 0 before the first event.
  QueueWait();
  Leases();
  Finished();
  Rescued();
  return std::make_shared<metrics::CallbackCollectable>([queue] {
    std::vector<prometheus::MetricFamily> out;
    absl::StatusOr<QueueStats> stats = queue->Stats();
    if (!stats.ok()) return out;
    prometheus::MetricFamily jobs =
        metrics::GaugeFamily("instascene_jobs", "Jobs by stage and state");
    for (const QueueStats::StageState& s : stats->jobs_by_stage) {
      metrics::AddGauge(&jobs, {{"stage", s.stage}, {"state", s.state}},
                        static_cast<double>(s.jobs));
    }
    prometheus::MetricFamily age = metrics::GaugeFamily(
        "instascene_queue_oldest_queued_age_seconds", "Age of the oldest queued job, by stage");
    for (const auto& [stage, ms] : stats->oldest_queued_age_ms_by_stage) {
      metrics::AddGauge(&age, {{"stage", stage}}, ms / 1000.0);
    }
    prometheus::MetricFamily scenes =
        metrics::GaugeFamily("instascene_scenes", "Scenes with at least one job");
    metrics::AddGauge(&scenes, {}, static_cast<double>(stats->scenes));
    out.push_back(std::move(jobs));
    out.push_back(std::move(age));
    out.push_back(std::move(scenes));
    return out;
  });
}

}  // namespace instascene::scheduler
