// Memory estimates: every shipped stage's estimate bounds what it really allocates (the peak RSS
// above the process's resident set before it ran, measured with the kernel's resettable
// high-water mark), and a job over the budget is refused before the stage runs.
#include <malloc.h>

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "common/core/testing/temp_dir.h"
#include "common/synth/scene_writer.h"
#include "services/pipeline/memory.h"
#include "services/pipeline/registry.h"
#include "services/stages/all_stages.h"

namespace instascene::pipeline {
namespace {
namespace fs = std::filesystem;

// VmRSS or VmHWM of this process, bytes.
int64_t StatusBytes(const std::string& key) {
  std::ifstream in("/proc/self/status");
  for (std::string line; std::getline(in, line);)
    if (line.rfind(key + ":", 0) == 0) return std::stoll(line.substr(key.size() + 1)) * 1024;
  return -1;
}

// The stage's own peak: the high-water mark (reset first) above the resident set before it ran.
struct Measured {
  int64_t estimate = 0, peak = 0;
};
Measured RunMeasured(const StageRegistry& r, const std::string& kind, const StageContext& c) {
  Measured m;
  auto estimate = r.Find(kind)->estimate(c);
  EXPECT_TRUE(estimate.ok()) << estimate.status();
  m.estimate = estimate.ok() ? *estimate : 0;
  malloc_trim(0);
  std::ofstream("/proc/self/clear_refs") << "5";  // resets VmHWM to the current RSS
  const int64_t before = StatusBytes("VmRSS");
  auto ran = r.Run(kind, c);
  EXPECT_TRUE(ran.ok()) << kind << ": " << ran.status();
  m.peak = StatusBytes("VmHWM") - before;
  return m;
}

TEST(MemoryEstimate, EveryStageStaysWithinItsEstimate) {
#if defined(__SANITIZE_ADDRESS__)
  // The resident set of an AddressSanitizer build holds its shadow memory and the quarantine of
  // freed blocks (train's peak 315 MiB there against 213 estimated): no measure of the stage.
  GTEST_SKIP() << "peak RSS is not the stage's own under AddressSanitizer";
#endif
  const testing::ScopedTempDir temp("memory_estimate");
  const std::string root = temp.str(), scene = root + "/scene";
  ASSERT_TRUE(WriteClutterScene(*GenerateClutterScene(*ClutterPreset("small")), scene).ok());
  StageRegistry r;
  ASSERT_TRUE(stages::RegisterStages(&r).ok());
  auto context = [&](const std::string& kind, nlohmann::json parameters) {
    StageContext c;
    c.scene_dir = scene;
    c.out_dir = root + "/" + kind;
    c.parameters = *r.Canonicalize(kind, parameters);
    c.num_threads = 2;
    fs::create_directories(c.out_dir);
    return c;
  };
  std::vector<std::pair<std::string, Measured>> results;
  StageContext c = context("decompose", nlohmann::json::object());
  results.emplace_back("decompose", RunMeasured(r, "decompose", c));
  c = context("train", {{"iterations", 100}});
  c.inputs["decompose"] = root + "/decompose";
  results.emplace_back("train", RunMeasured(r, "train", c));
  c = context("segment", nlohmann::json::object());
  c.inputs["train"] = root + "/train";
  results.emplace_back("segment", RunMeasured(r, "segment", c));
  c = context("complete", nlohmann::json::object());
  c.inputs["segment"] = root + "/segment";
  c.item = 0;
  results.emplace_back("complete", RunMeasured(r, "complete", c));
  c = context("export", nlohmann::json::object());
  c.inputs["segment"] = root + "/segment";
  c.inputs["complete/0"] = root + "/complete";
  results.emplace_back("export", RunMeasured(r, "export", c));
  for (const auto& [kind, m] : results) {
    std::printf("%-9s estimate %6.1f MiB, measured peak %6.1f MiB\n", kind.c_str(),
                m.estimate / double(kMiB), m.peak / double(kMiB));
    EXPECT_GE(m.estimate, m.peak) << kind << " allocated more than it estimated";
    EXPECT_LE(m.estimate, 8 * m.peak + 256 * kMiB)
        << kind << ": an estimate that refuses for nothing";
  }
}

TEST(MemoryEstimate, AJobOverTheBudgetIsRefusedBeforeItRuns) {
  const testing::ScopedTempDir temp("memory_budget");
  const std::string scene = temp.Sub("scene");
  const absl::StatusOr<ClutterScene> tiny = GenerateClutterScene(*ClutterPreset("tiny"));
  ASSERT_TRUE(tiny.ok() && WriteClutterScene(*tiny, scene).ok());
  StageRegistry r;
  ASSERT_TRUE(stages::RegisterStages(&r).ok());
  StageContext c;
  c.scene_dir = scene;
  c.out_dir = temp.Sub("out");
  c.memory_budget_bytes = 16 * kMiB;
  const auto refused = r.Run("decompose", c);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_NE(refused.status().message().find("--memory-budget-bytes"), std::string::npos);
  EXPECT_FALSE(fs::exists(c.out_dir)) << "nothing ran";
  c.memory_budget_bytes = 0;  // no limit
  EXPECT_TRUE(r.Run("decompose", c).ok());
  // The footprint is read from headers only.
  auto f = ReadSceneFootprint(scene);
  ASSERT_TRUE(f.ok()) << f.status();
  EXPECT_EQ(f->views, 12);
  EXPECT_EQ(f->max_view_pixels, 96 * 72);
  EXPECT_EQ(f->gaussians, tiny->cloud.size());
  EXPECT_FALSE(ReadSceneFootprint(temp.Sub("nowhere")).ok());
}

}  // namespace
}  // namespace instascene::pipeline
