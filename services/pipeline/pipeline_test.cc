#include <gtest/gtest.h>

#include <filesystem>

#include "common/core/testing/temp_dir.h"
#include "common/eval/result.h"
#include "common/scene/scene.h"
#include "common/synth/scene_writer.h"
#include "services/pipeline/local_runner.h"
#include "services/stages/all_stages.h"
#include "services/training/segmentation.h"

namespace instascene::pipeline {
namespace {
namespace fs = std::filesystem;

StageRegistry Stages() {
  StageRegistry r;
  EXPECT_TRUE(stages::RegisterStages(&r).ok());
  return r;
}

TEST(Registry, CodecsValidateAndCanonicalize) {
  const StageRegistry r = Stages();
  EXPECT_EQ(r.Kinds(),
            (std::vector<std::string>{"decompose", "train", "segment", "complete", "export"}));
  // export is a partial join (it runs over the completions that succeeded): in the default.
  EXPECT_EQ(r.DefaultStages(),
            (std::vector<std::string>{"decompose", "train", "segment", "complete", "export"}));
  // Defaults are filled in: {} and the explicit defaults are the same job.
  auto a = r.Canonicalize("train", nlohmann::json::object());
  auto b = r.Canonicalize("train", {{"iterations", 1500}, {"supervision", "full"}});
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(*a, *b);
  EXPECT_EQ((*a)["iterations"], 1500);
  EXPECT_EQ((*a)["method"], "contrastive");
  EXPECT_EQ((*r.Canonicalize("decompose", {{"tracker_rule", "median"}}))["tracker_rule"], "median");
  struct Bad {
    std::string kind;
    nlohmann::json p;
    std::string says;
  };
  for (const Bad& c : std::vector<Bad>{
           {"train", {{"iterations", "many"}}, "'iterations' must be an integer"},
           {"train", {{"iterations", 0}}, "outside [1, 1e+06]"},
           {"train", {{"iterations", -1}}, "iterations"},
           {"train", {{"samples", 2147483647}}, "samples"},
           {"train", {{"iterations", 10.5}}, "must be an integer"},
           {"train", {{"supervision", "psychic"}}, "psychic"},
           {"train", {{"method", "magic"}}, "magic"},
           {"segment", {{"threshold", 2.0}}, "threshold"},
           {"segment", {{"threshold", -1.0}}, "not in (-1, 1]"},
           {"segment", {{"tau", 0.9}}, "unknown parameter 'tau' (known: labelling, threshold"},
           {"segment", {{"labelling", "kmeans"}}, "kmeans"},
           {"segment", {{"max_points", 50000}}, "max_points"},
           {"decompose", {{"dbscan_eps", -1.0}}, "stage decompose"},
           {"decompose", {{"dbscan_eps_relative", 1}}, "true or false"},
           {"render", nlohmann::json::object(), "unknown stage 'render'"},
           {"segment", nlohmann::json::array(), "must be a JSON object"},
           {"complete", {{"prior", "magic"}}, "magic"},
           {"complete", {{"ring_views", 1000}}, "ring_views"}}) {
    const absl::Status s = r.Canonicalize(c.kind, c.p).status();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << c.p.dump();
    EXPECT_NE(s.message().find(c.says), std::string::npos) << s;
  }
}

TEST(Registry, PlansPipelinesAndRefusesBadOnes) {
  const StageRegistry r = Stages();
  auto plan = r.Plan({}, {{"train", {{"iterations", 50}}}});
  ASSERT_TRUE(plan.ok()) << plan.status();
  ASSERT_EQ(plan->size(), 5u);
  EXPECT_EQ((*plan)[4].inputs[0].mode, InputMode::kAll);
  EXPECT_EQ((*plan)[1].parameters["iterations"], 50);
  EXPECT_EQ((*plan)[2].inputs.size(), 1u);
  EXPECT_EQ((*plan)[2].inputs[0].stage, "train");
  EXPECT_EQ((*plan)[3].inputs[0].stage, "segment");
  EXPECT_EQ((*plan)[3].inputs[0].mode, InputMode::kEach);
  EXPECT_EQ(r.Plan({"decompose"}, nlohmann::json::object())->size(), 1u);
  for (const auto& [stages, params] :
       std::vector<std::pair<std::vector<std::string>, nlohmann::json>>{
           {{"train", "segment"}, nlohmann::json::object()},        // train needs decompose
           {{}, {{"render", nlohmann::json::object()}}},            // not in the pipeline
           {{"decompose"}, {{"train", nlohmann::json::object()}}},  // not in the pipeline
           {{"decompose", "decompose"}, nlohmann::json::object()},
           {{}, {{"train", {{"iterations", -5}}}}},
           {{}, nlohmann::json::array()}}) {
    EXPECT_EQ(r.Plan(stages, params).status().code(), absl::StatusCode::kInvalidArgument)
        << params.dump();
  }
  // Registration checks inputs.
  StageRegistry bad;
  StageSpec orphan;
  orphan.kind = "orphan";
  orphan.inputs = {{"nothing", InputMode::kOne}};
  orphan.canonicalize = [](const nlohmann::json& p) -> absl::StatusOr<nlohmann::json> { return p; };
  EXPECT_EQ(bad.Add({orphan, nullptr}).code(), absl::StatusCode::kInvalidArgument);
  StageRegistry twice = Stages();
  EXPECT_EQ(stages::RegisterStageSpecs(&twice).code(), absl::StatusCode::kAlreadyExists);
  // A spec-only registry validates but cannot run.
  StageRegistry specs;
  ASSERT_TRUE(stages::RegisterStageSpecs(&specs).ok());
  EXPECT_TRUE(specs.RunnableKinds().empty());
  EXPECT_EQ(specs.Run("decompose", StageContext{}).status().code(),
            absl::StatusCode::kUnimplemented);
}

TEST(Registry, AStageThatThrowsFailsItsJobNotTheProcess) {
  StageRegistry r;
  auto spec = [](const std::string& kind) {
    StageSpec s;
    s.kind = kind;
    s.canonicalize = [](const nlohmann::json& p) -> absl::StatusOr<nlohmann::json> { return p; };
    return s;
  };
  ASSERT_TRUE(
      r.Add({spec("hungry"),
             [](const StageContext&) -> absl::StatusOr<StageResult> { throw std::bad_alloc(); }})
          .ok());
  ASSERT_TRUE(r.Add({spec("broken"),
                     [](const StageContext&) -> absl::StatusOr<StageResult> {
                       throw std::runtime_error("index out of range");
                     }})
                  .ok());
  const auto hungry = r.Run("hungry", StageContext{});
  EXPECT_EQ(hungry.status().code(), absl::StatusCode::kResourceExhausted);
  const auto broken = r.Run("broken", StageContext{});
  EXPECT_EQ(broken.status().code(), absl::StatusCode::kInternal);
  EXPECT_NE(broken.status().message().find("index out of range"), std::string::npos);
}

TEST(LocalRunner, APartialJoinRunsOverTheItemsThatSucceeded) {
  const testing::ScopedTempDir temp("pipeline_partial");
  StageRegistry r;
  auto spec = [](const std::string& kind, std::vector<PlannedInput> inputs) {
    StageSpec s;
    s.kind = kind;
    s.inputs = std::move(inputs);
    s.canonicalize = [](const nlohmann::json& p) -> absl::StatusOr<nlohmann::json> { return p; };
    return s;
  };
  StageSpec source = spec("source", {});
  source.fans_out = true;
  ASSERT_TRUE(
      r.Add({source,
             [](const StageContext&) -> absl::StatusOr<StageResult> { return StageResult{3}; }})
          .ok());
  ASSERT_TRUE(r.Add({spec("each", {{"source", InputMode::kEach}}),
                     [](const StageContext& c) -> absl::StatusOr<StageResult> {
                       if (c.item == 1) return absl::InvalidArgumentError("degenerate item");
                       return StageResult{};
                     }})
                  .ok());
  std::vector<std::string> seen;
  StageSpec partial = spec("partial", {{"each", InputMode::kAll}});
  partial.partial_join = true;
  ASSERT_TRUE(r.Add({partial,
                     [&](const StageContext& c) -> absl::StatusOr<StageResult> {
                       for (const auto& [name, dir] : c.inputs) seen.push_back(name);
                       return StageResult{};
                     }})
                  .ok());
  ASSERT_TRUE(
      r.Add({spec("strict", {{"each", InputMode::kAll}}),
             [](const StageContext&) -> absl::StatusOr<StageResult> { return StageResult{}; }})
          .ok());
  LocalRunOptions options;
  options.out_dir = temp.str();
  auto plan = r.Plan({"source", "each", "partial"}, nlohmann::json::object());
  ASSERT_TRUE(plan.ok()) << plan.status();
  auto run = RunPipelineLocally(r, *plan, options);
  ASSERT_TRUE(run.ok()) << run.status();
  EXPECT_EQ(seen, (std::vector<std::string>{"each/0", "each/2"}));
  EXPECT_EQ(run->failures.count("each/1"), 1u);
  auto strict = r.Plan({"source", "each", "strict"}, nlohmann::json::object());
  ASSERT_TRUE(strict.ok());
  EXPECT_EQ(RunPipelineLocally(r, *strict, options).status().code(),
            absl::StatusCode::kFailedPrecondition);
}

TEST(LocalRunner, ThreeStagesGiveTheTauRuleLabelsAndCancelStops) {
  const testing::ScopedTempDir temp("pipeline_stages");
  const std::string root = temp.str();
  const std::string scene_dir = (fs::path(root) / "scene").string();
  auto generated = GenerateClutterScene(*ClutterPreset("tiny"));
  ASSERT_TRUE(generated.ok());
  ASSERT_TRUE(WriteClutterScene(*generated, scene_dir).ok());
  const StageRegistry r = Stages();
  auto plan = r.Plan({"decompose", "train", "segment"}, {{"train", {{"iterations", 60}}}});
  ASSERT_TRUE(plan.ok());
  std::vector<std::string> phases;
  LocalRunOptions options;
  options.scene_dir = scene_dir;
  options.out_dir = root + "/out";
  options.progress = [&](const std::string& kind, int64_t, const StageProgress& p) {
    phases.push_back(kind + ":" + p.phase);
  };
  auto run = RunPipelineLocally(r, *plan, options);
  ASSERT_TRUE(run.ok()) << run.status();
  EXPECT_NE(std::find(phases.begin(), phases.end(), "decompose:tracking"), phases.end());
  EXPECT_NE(std::find(phases.begin(), phases.end(), "train:training"), phases.end());
  const std::string train = root + "/out/training", seg = root + "/out/segmentation";
  EXPECT_EQ(run->outputs.at("segment"), seg);

  auto scene = ReadScene(scene_dir);
  auto cloud = ReadSceneGaussians(*scene);
  auto trained = ReadResult(train, cloud->size());
  auto segmented = ReadResult(seg, cloud->size());
  ASSERT_TRUE(trained.ok() && segmented.ok());
  EXPECT_EQ(trained->feature_dim, 16);
  EXPECT_EQ(segmented->labels,
            training::SegmentByFeatures(trained->features, 16, trained->labels, cloud->positions,
                                        training::SegmentOptions{0.9}));
  EXPECT_TRUE(fs::exists(fs::path(seg) / "instances.json"));
  // segment fans out over its instances.
  std::set<uint32_t> ids(segmented->labels.begin(), segmented->labels.end());
  ids.erase(0);
  EXPECT_EQ(run->items.at("segment"), static_cast<int64_t>(ids.size()));

  // A set cancel flag stops a stage with Cancelled.
  CancelFlag cancel{true};
  StageContext c;
  c.scene_dir = scene_dir;
  c.out_dir = root + "/cancelled";
  c.cancel = &cancel;
  EXPECT_EQ(r.Run("decompose", c).status().code(), absl::StatusCode::kCancelled);
  // A stage without its input is refused before it runs.
  c.cancel = nullptr;
  EXPECT_EQ(r.Run("train", c).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace instascene::pipeline
