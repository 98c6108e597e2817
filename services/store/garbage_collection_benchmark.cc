// Time of a garbage collection of the embedded default's store (filesystem store + SQLite queue):
// a dry run (list every blob, read every job's two manifests, sweep) over stores of N jobs, each
// job a scene manifest of 20 files and an output manifest of 10, plus 8 unreachable blobs per
// job; the store is built once per size and removed when the benchmark ends. Counters: blobs
// and jobs, and the time per blob.
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <filesystem>
#include <map>
#include <memory>

#include "absl/strings/str_cat.h"
#include "common/store/manifest.h"
#include "services/scheduler/sqlite_queue_store.h"
#include "services/store/garbage_collection.h"

namespace instascene::store_service {
namespace {

class GcFixture {
 public:
  explicit GcFixture(int jobs)
      : dir_(std::filesystem::temp_directory_path() /
             absl::StrCat("gc_bench_", jobs, "_", ::getpid())) {
    std::filesystem::remove_all(dir_);
    store_ = std::move(*store::FilesystemBlobStore::Open((dir_ / "store").string(), {}));
    queue_ = std::move(*scheduler::OpenSqliteJobQueue((dir_ / "jobs.db").string(), {}));
    for (int j = 0; j < jobs; ++j) AddJob(j);
  }
  ~GcFixture() {
    queue_.reset();
    store_.reset();
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  store::FilesystemBlobStore& store() { return *store_; }
  scheduler::JobQueue& queue() { return *queue_; }

 private:
  store::Digest Blob(const std::string& bytes) {
    const store::Digest d = store::ComputeDigest(bytes);
    (void)store_->Put(d, bytes);
    return d;
  }
  store::Digest Manifest(const std::string& kind, int job, int files) {
    store::Manifest m;
    m.kind = kind;
    for (int f = 0; f < files; ++f)
      m.files[absl::StrCat("f", f)] = Blob(absl::StrCat(kind, " ", job, " file ", f));
    return Blob(store::SerializeManifest(m));
  }
  void AddJob(int j) {
    scheduler::SubmitRequest request;
    request.scene = absl::StrCat("s", j);
    request.scene_manifest = Manifest("scene", j, 20);
    request.stages = {{"decompose", {{"p", 1}}, {}}};
    (void)queue_->Submit(request);
    auto lease = queue_->LeaseNext({"decompose"}, "w");
    (void)queue_->Complete((*lease)->job.id, (*lease)->token, Manifest("decompose", j, 10));
    for (int o = 0; o < 8; ++o) Blob(absl::StrCat("orphan ", j, " ", o));
  }

  const std::filesystem::path dir_;
  std::unique_ptr<store::FilesystemBlobStore> store_;
  std::unique_ptr<scheduler::JobQueue> queue_;
};

void BM_GcDryRun(benchmark::State& state) {
  GcFixture fixture(static_cast<int>(state.range(0)));
  GcOptions options;
  options.dry_run = true;
  options.grace = std::chrono::seconds(0);
  GcReport report;
  for (auto _ : state) report = *CollectGarbage(fixture.store(), fixture.queue(), options);
  state.counters["jobs"] = static_cast<double>(report.jobs);
  state.counters["blobs"] = static_cast<double>(report.blobs);
  state.counters["unreachable"] = static_cast<double>(report.removed_blobs);
  state.counters["per_blob"] = benchmark::Counter(
      static_cast<double>(report.blobs),
      benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_GcDryRun)->Arg(30)->Arg(300)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace instascene::store_service

BENCHMARK_MAIN();
