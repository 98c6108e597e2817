// Throughput of the SQLite job queue (durable: WAL + synchronous=FULL, one fsync per commit):
// a full job cycle (submit, lease, heartbeat, complete) and a lease scan over a deep queue.
#include <benchmark/benchmark.h>

#include <unistd.h>

#include <filesystem>

#include "common/store/digest.h"
#include "services/scheduler/sqlite_queue_store.h"

namespace instascene::scheduler {
namespace {

// A queue in a fresh directory, removed when the benchmark ends.
struct BenchQueue {
  explicit BenchQueue(const std::string& name)
      : dir(std::filesystem::temp_directory_path() /
            ("queue_bench_" + name + "_" + std::to_string(::getpid()))) {
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    queue = std::move(*OpenSqliteJobQueue((dir / "jobs.db").string(), QueueOptions{}));
  }
  ~BenchQueue() {
    queue.reset();
    std::filesystem::remove_all(dir);
  }
  JobQueue* operator->() { return queue.get(); }
  std::filesystem::path dir;
  std::unique_ptr<JobQueue> queue;
};

SubmitRequest Spec(int64_t i) {
  SubmitRequest s;
  s.scene = "scene" + std::to_string(i % 16);
  s.scene_manifest = store::ComputeDigest(std::to_string(i));
  s.stages = {{"decompose", nlohmann::json::object(), {}}};
  return s;
}

void BM_JobCycle(benchmark::State& state) {
  BenchQueue queue("cycle");
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
  BenchQueue queue("deep");
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
