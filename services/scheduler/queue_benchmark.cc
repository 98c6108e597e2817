// Throughput of the SQLite job queue (durable: WAL + synchronous=FULL, one fsync per commit):
// a full job cycle (submit, lease, heartbeat, complete) and a lease scan over a deep queue.
#include <benchmark/benchmark.h>

#include <filesystem>

#include "common/store/digest.h"
#include "services/scheduler/sqlite_job_queue.h"

namespace instascene::scheduler {
namespace {

std::unique_ptr<SqliteJobQueue> FreshQueue(const std::string& name) {
  const std::string dir = std::filesystem::temp_directory_path() / ("queue_bench_" + name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return std::move(*SqliteJobQueue::Open(dir + "/jobs.db", QueueOptions{}));
}

JobSpec Spec(int64_t i) {
  JobSpec s;
  s.scene = "scene" + std::to_string(i % 16);
  s.kind = "decompose";
  s.scene_manifest = store::ComputeDigest(std::to_string(i));
  return s;
}

void BM_JobCycle(benchmark::State& state) {
  auto queue = FreshQueue("cycle");
  int64_t i = 0;
  for (auto _ : state) {
    auto submitted = queue->Submit(Spec(i++));
    auto lease = queue->LeaseNext({"decompose"}, "w", 0);
    benchmark::DoNotOptimize(queue->Heartbeat((*lease)->job.id, (*lease)->token, {}));
    benchmark::DoNotOptimize(
        queue->Complete((*lease)->job.id, (*lease)->token, store::ComputeDigest("out")));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_JobCycle)->Unit(benchmark::kMillisecond);

// Leasing from a queue holding `depth` ready jobs of 16 scenes (the fairness ordering scans them).
void BM_LeaseFromDeepQueue(benchmark::State& state) {
  auto queue = FreshQueue("deep");
  const int64_t depth = state.range(0);
  for (int64_t i = 0; i < depth; ++i) benchmark::DoNotOptimize(queue->Submit(Spec(i)));
  int64_t next = depth;
  for (auto _ : state) {
    auto lease = queue->LeaseNext({"decompose"}, "w", 0);
    state.PauseTiming();
    benchmark::DoNotOptimize(
        queue->Complete((*lease)->job.id, (*lease)->token, store::ComputeDigest("out")));
    benchmark::DoNotOptimize(queue->Submit(Spec(next++)));  // keep the depth constant
    state.ResumeTiming();
  }
}
BENCHMARK(BM_LeaseFromDeepQueue)->Arg(100)->Arg(10000)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace instascene::scheduler

BENCHMARK_MAIN();
