#include <gtest/gtest.h>

#include <filesystem>

#include "common/core/testing/temp_dir.h"
#include "common/eval/result.h"
#include "common/scene/scene.h"
#include "common/synth/scene_writer.h"
#include "services/pipeline/stages.h"
#include "services/training/segmentation.h"

namespace instascene::pipeline {
namespace {
namespace fs = std::filesystem;

TEST(StagesTest, ParametersAreValidated) {
  EXPECT_TRUE(ValidateParameters("decompose", nlohmann::json::object()).ok());
  EXPECT_TRUE(ValidateParameters("train", {{"iterations", 10}, {"supervision", "3d"}}).ok());
  EXPECT_TRUE(ValidateParameters("segment", {{"threshold", 0.8}}).ok());
  struct Bad {
    std::string kind;
    nlohmann::json p;
    std::string says;
  };
  for (const Bad& b :
       std::vector<Bad>{{"train", {{"iterations", "many"}}, "'iterations' has the wrong type"},
                        {"train", {{"iterations", 0}}, "iterations"},
                        {"train", {{"supervision", "psychic"}}, "psychic"},
                        {"train", {{"method", "magic"}}, "magic"},
                        {"segment", {{"threshold", 2.0}}, "threshold 2"},
                        {"segment", {{"tau", 0.9}}, "unknown parameter 'tau'"},
                        {"decompose", {{"dbscan_eps", -1.0}}, "decompose"},
                        {"render", nlohmann::json::object(), "unknown stage 'render'"},
                        {"segment", nlohmann::json::array(), "must be an object"}}) {
    const absl::Status s = ValidateParameters(b.kind, b.p);
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << b.p.dump();
    EXPECT_NE(s.message().find(b.says), std::string::npos) << s;
  }
}

TEST(StagesTest, ThreeStagesGiveTheTauRuleLabelsAndCancelStops) {
  const std::string root = testing::FreshTempDir("pipeline_stages");
  const std::string scene_dir = (fs::path(root) / "scene").string();
  auto generated = GenerateClutterScene(*ClutterPreset("tiny"));
  ASSERT_TRUE(generated.ok());
  ASSERT_TRUE(WriteClutterScene(*generated, scene_dir).ok());
  const std::string dec = root + "/decompose", train = root + "/train", seg = root + "/segment";
  std::vector<std::string> phases;
  StageContext c;
  c.scene_dir = scene_dir;
  c.progress = [&](const StageProgress& p) { phases.push_back(p.phase); };
  c.out_dir = dec;
  ASSERT_TRUE(RunStage("decompose", c).ok());
  EXPECT_NE(std::find(phases.begin(), phases.end(), "tracking"), phases.end());
  c.input_dir = dec;
  c.out_dir = train;
  c.parameters = {{"iterations", 60}};
  ASSERT_TRUE(RunStage("train", c).ok());
  EXPECT_NE(std::find(phases.begin(), phases.end(), "training"), phases.end());
  c.input_dir = train;
  c.out_dir = seg;
  c.parameters = nlohmann::json::object();
  ASSERT_TRUE(RunStage("segment", c).ok());

  auto scene = ReadScene(scene_dir);
  auto cloud = ReadSceneGaussians(*scene);
  auto trained = ReadResult(train, cloud->size());
  auto segmented = ReadResult(seg, cloud->size());
  ASSERT_TRUE(trained.ok() && segmented.ok());
  EXPECT_EQ(trained->feature_dim, 16);
  EXPECT_EQ(segmented->labels, training::SegmentByFeatures(trained->features, 16, trained->labels,
                                                           training::SegmentOptions{0.9}));
  EXPECT_TRUE(fs::exists(fs::path(seg) / "instances.json"));

  // A set cancel flag stops a stage with Cancelled.
  CancelFlag cancel{true};
  c.cancel = &cancel;
  c.input_dir = "";
  c.out_dir = root + "/cancelled";
  EXPECT_EQ(RunStage("decompose", c).code(), absl::StatusCode::kCancelled);
}

}  // namespace
}  // namespace instascene::pipeline
