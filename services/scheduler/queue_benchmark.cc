// Throughput of the job queue on both storage backends: SQLite (durable: WAL + synchronous=FULL,
// one fsync per commit) and PostgreSQL (a server this benchmark starts on a Unix socket, fsync off
// as in the tests, so the figure is the queue's own cost, not the disk's): a full job cycle
// (submit, lease, heartbeat, complete) and a lease over a deep queue. Argument 0 = SQLite,
// 1 = PostgreSQL.
#include <benchmark/benchmark.h>

#include <unistd.h>

#include <cstdio>
#include <filesystem>

#include "common/store/digest.h"
#include "services/scheduler/postgres_queue_store.h"
#include "services/scheduler/sqlite_queue_store.h"
#include "services/scheduler/testing/postgres_server.h"

namespace instascene::scheduler {
namespace {

testing::PostgresServer* Postgres() {
  static std::unique_ptr<testing::PostgresServer> server = [] {
    auto s = testing::PostgresServer::Start();
    if (!s.ok()) std::fprintf(stderr, "no PostgreSQL: %s\n", s.status().ToString().c_str());
    return s.ok() ? std::move(*s) : nullptr;
  }();
  return server.get();
}

// A queue in a fresh directory (SQLite) or schema (PostgreSQL), removed when the benchmark ends.
struct BenchQueue {
  BenchQueue(const std::string& name, int backend)
      : dir(std::filesystem::temp_directory_path() /
            ("queue_bench_" + name + "_" + std::to_string(::getpid()))) {
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    if (backend == 0) {
      queue = std::move(*OpenSqliteJobQueue((dir / "jobs.db").string(), QueueOptions{}));
    } else {
      static int schemas = 0;
      auto store = PostgresQueueStore::Open(Postgres()->conninfo(),
                                            "bench_" + name + std::to_string(schemas++));
      queue = std::make_unique<JobQueue>(std::move(*store), QueueOptions{});
    }
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
  BenchQueue queue("cycle", static_cast<int>(state.range(0)));
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
BENCHMARK(BM_JobCycle)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// Leasing from a queue holding `depth` ready jobs of 16 scenes (the fairness ordering scans them).
void BM_LeaseFromDeepQueue(benchmark::State& state) {
  BenchQueue queue("deep", static_cast<int>(state.range(0)));
  const int64_t depth = state.range(1);
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
BENCHMARK(BM_LeaseFromDeepQueue)
    ->Args({0, 100})
    ->Args({0, 10000})
    ->Args({1, 100})
    ->Args({1, 10000})
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace instascene::scheduler

BENCHMARK_MAIN();
