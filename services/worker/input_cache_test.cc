#include "services/worker/input_cache.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "common/core/testing/temp_dir.h"
#include "services/worker/stage_worker.h"

namespace instascene::worker {
namespace {
namespace fs = std::filesystem;

void MakeEntry(const fs::path& dir, size_t bytes, int age_s) {
  fs::create_directories(dir / "sub");
  std::ofstream(dir / "sub" / "data.bin", std::ios::binary) << std::string(bytes, 'x');
  fs::last_write_time(dir, fs::file_time_type::clock::now() - std::chrono::seconds(age_s));
}

TEST(InputCache, EvictsLeastRecentlyUsedFirstAndKeepsWhatTheJobNeeds) {
  const testing::ScopedTempDir temp("input_cache");
  const fs::path root = temp.path();
  MakeEntry(root / "scenes" / "a", 1000, 300);  // oldest
  MakeEntry(root / "scenes" / "b", 1000, 200);
  MakeEntry(root / "results" / "c", 1000, 100);
  MakeEntry(root / "results" / "d", 1000, 10);  // newest
  const std::vector<std::string> roots = {(root / "scenes").string(), (root / "results").string()};

  auto unlimited = EvictCache(roots, 0, {});
  ASSERT_TRUE(unlimited.ok());
  EXPECT_EQ(unlimited->bytes_before, 4000);
  EXPECT_TRUE(unlimited->evicted.empty());

  // Budget 2500 bytes, "a" needed by the current job: b then c go (oldest first), a stays.
  auto report = EvictCache(roots, 2500, {(root / "scenes" / "a").string()});
  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_EQ(report->evicted, (std::vector<std::string>{(root / "scenes" / "b").string(),
                                                       (root / "results" / "c").string()}));
  EXPECT_EQ(report->bytes_after, 2000);
  EXPECT_TRUE(fs::exists(root / "scenes" / "a"));
  EXPECT_TRUE(fs::exists(root / "results" / "d"));

  // Touching makes an entry the most recent.
  TouchCacheEntry((root / "scenes" / "a").string());
  report = EvictCache(roots, 1000, {});
  ASSERT_TRUE(report.ok());
  EXPECT_EQ(report->evicted, (std::vector<std::string>{(root / "results" / "d").string()}));
  EXPECT_TRUE(fs::exists(root / "scenes" / "a"));
}

TEST(WorkerOptions, Validate) {
  // A registry with one runnable stage and one known only by its spec.
  pipeline::StageRegistry stages;
  auto spec = [](const std::string& kind) {
    pipeline::StageSpec s;
    s.kind = kind;
    s.canonicalize = [](const nlohmann::json& p) -> absl::StatusOr<nlohmann::json> { return p; };
    return s;
  };
  ASSERT_TRUE(stages
                  .Add({spec("decompose"),
                        [](const pipeline::StageContext&) { return pipeline::StageResult{}; }})
                  .ok());
  ASSERT_TRUE(stages.Add({spec("train"), nullptr}).ok());
  WorkerOptions o;
  o.kinds = {"decompose"};
  o.work_dir = "work";
  EXPECT_TRUE(o.Validate(stages).ok());
  WorkerOptions bad = o;
  bad.kinds = {"render"};
  EXPECT_EQ(bad.Validate(stages).code(), absl::StatusCode::kInvalidArgument);
  bad.kinds = {"train"};  // known, but this binary cannot run it
  EXPECT_EQ(bad.Validate(stages).code(), absl::StatusCode::kInvalidArgument);
  bad = o;
  bad.kinds.clear();
  EXPECT_EQ(bad.Validate(stages).code(), absl::StatusCode::kInvalidArgument);
  bad = o;
  bad.work_dir.clear();
  EXPECT_EQ(bad.Validate(stages).code(), absl::StatusCode::kInvalidArgument);
  bad = o;
  bad.heartbeat_interval_ms = 0;
  EXPECT_EQ(bad.Validate(stages).code(), absl::StatusCode::kInvalidArgument);
  bad = o;
  bad.cache_bytes = -1;
  EXPECT_EQ(bad.Validate(stages).code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace instascene::worker
