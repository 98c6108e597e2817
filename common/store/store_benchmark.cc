// Throughput of the filesystem blob store: verified small puts (hash + temp + fsync + rename) and
// large chunked uploads (append + final hash + fsync + rename), and SHA-256 itself.
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <filesystem>
#include <random>

#include "common/store/blob_store.h"

namespace instascene::store {
namespace {

std::string RandomBytes(size_t n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::string s(n, '\0');
  for (size_t i = 0; i + 8 <= n; i += 8) {
    const uint64_t v = rng();
    std::memcpy(&s[i], &v, 8);
  }
  return s;
}

// A store in a fresh temporary folder, removed when the benchmark ends.
struct FreshStore {
  explicit FreshStore(const std::string& name)
      : dir(std::filesystem::temp_directory_path() /
            ("store_bench_" + name + "_" + std::to_string(::getpid()))) {
    std::filesystem::remove_all(dir);
    store = std::move(*FilesystemBlobStore::Open(dir.string(), StoreOptions{}));
  }
  ~FreshStore() {
    store.reset();
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
  FilesystemBlobStore* operator->() { return store.get(); }

  std::filesystem::path dir;
  std::unique_ptr<FilesystemBlobStore> store;
};

void BM_Sha256(benchmark::State& state) {
  const std::string data = RandomBytes(static_cast<size_t>(state.range(0)), 1);
  for (auto _ : state) benchmark::DoNotOptimize(ComputeDigest(data));
  state.SetBytesProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_Sha256)->Arg(1 << 20)->Arg(64 << 20)->Unit(benchmark::kMillisecond);

void BM_PutSmallBlob(benchmark::State& state) {
  FreshStore store("small");
  uint64_t seed = 0;
  for (auto _ : state) {
    state.PauseTiming();
    const std::string data = RandomBytes(static_cast<size_t>(state.range(0)), ++seed);
    const Digest d = ComputeDigest(data);
    state.ResumeTiming();
    benchmark::DoNotOptimize(store->Put(d, data));
  }
  state.SetBytesProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_PutSmallBlob)->Arg(4 << 10)->Arg(1 << 20)->Unit(benchmark::kMillisecond);

void BM_ChunkedUpload(benchmark::State& state) {
  FreshStore store("large");
  uint64_t seed = 100;
  const size_t size = static_cast<size_t>(state.range(0));
  for (auto _ : state) {
    state.PauseTiming();
    const std::string data = RandomBytes(size, ++seed);
    const Digest d = ComputeDigest(data);
    state.ResumeTiming();
    for (size_t offset = 0; offset < size; offset += 1 << 20) {
      benchmark::DoNotOptimize(store->Append(d, static_cast<int64_t>(offset),
                                             absl::string_view(data).substr(offset, 1 << 20)));
    }
    benchmark::DoNotOptimize(store->FinishUpload(d));
  }
  state.SetBytesProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_ChunkedUpload)->Arg(64 << 20)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace instascene::store

BENCHMARK_MAIN();
