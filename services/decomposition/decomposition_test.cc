#include <gtest/gtest.h>

#include "common/core/testing/temp_dir.h"

#include <filesystem>

#include "common/eval/click_eval.h"
#include "common/synth/scene_writer.h"
#include "services/decomposition/decompose.h"

namespace instascene::decomposition {
namespace {

// End to end on small synthetic scenes; returns the evaluation of the decomposition.
ClickEvaluation DecomposeSynthetic(const std::string& noise, uint64_t seed) {
  const instascene::testing::ScopedTempDir temp("decomp_" + noise + std::to_string(seed));
  const std::string dir = temp.Sub("scene");
  ClutterOptions scene_options = *ClutterPreset("small");
  scene_options.seed = seed;
  absl::StatusOr<ClutterScene> scene = GenerateClutterScene(scene_options);
  EXPECT_TRUE(scene.ok());
  SceneWriteOptions write;
  write.mask_noise = noise;
  write.seed = seed;
  EXPECT_TRUE(WriteClutterScene(*scene, dir, write).ok());
  absl::StatusOr<Scene> read = ReadScene(dir);
  EXPECT_TRUE(read.ok());
  absl::StatusOr<DecompositionResult> result =
      Decompose(*read, scene->cloud, DecompositionOptions{});
  EXPECT_TRUE(result.ok()) << result.status();
  EXPECT_TRUE(WriteDecomposition(dir + "/decomposition", *read, scene->cloud, *result).ok());
  absl::StatusOr<ClickEvaluation> eval =
      EvaluateResultDirectory(dir, dir + "/decomposition", ClickEvalOptions{});
  EXPECT_TRUE(eval.ok()) << eval.status();
  return *eval;
}

// Every object visible (>= 20 GT pixels) in at least `min_views` views is recovered: some
// instance overlaps its observed Gaussians with IoU > 0.5.
void ExpectWellSeenObjectsRecovered(const ClickEvaluation& eval, int min_views) {
  int checked = 0;
  for (const ObjectClickScore& o : eval.objects) {
    if (o.views < min_views) continue;
    ++checked;
    EXPECT_GT(eval.instances.best_iou.at(o.id), 0.5)
        << o.name << " seen in " << o.views << " views";
  }
  EXPECT_GE(checked, 5);
}

TEST(Decompose, RecoversEveryWellSeenObjectWithoutNoise) {
  for (uint64_t seed : {1, 2}) {
    const ClickEvaluation eval = DecomposeSynthetic("none", seed);
    ExpectWellSeenObjectsRecovered(eval, 6);
    EXPECT_GT(eval.miou, 0.7);
    EXPECT_DOUBLE_EQ(eval.instances.precision, 1.0);
  }
}

TEST(Decompose, RecoversEveryWellSeenObjectAtLowNoise) {
  for (uint64_t seed : {1, 2}) ExpectWellSeenObjectsRecovered(DecomposeSynthetic("low", seed), 6);
}

}  // namespace
}  // namespace instascene::decomposition
