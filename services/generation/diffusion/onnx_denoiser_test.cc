#include "services/generation/diffusion/onnx_denoiser.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>

#include "common/core/testing/temp_dir.h"
#include "common/rpc/server.h"
#include "services/generation/diffusion/analytic_denoiser.h"
#include "services/generation/diffusion/grpc_denoiser.h"

namespace instascene::generation::diffusion {
namespace {

// The model is written at test time by Debian's python3-onnx (scripts/install-deps.sh).
void WriteModel(const std::string& path, const std::string& variant) {
  const std::string command = std::string("/usr/bin/python3 ") + INSTASCENE_SOURCE_DIR +
                              "/tests/diffusion/analytic_denoiser_onnx.py " + path +
                              " 2 4 4 0.25 " + variant;
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
}

void WriteText(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

const char* kConfig = R"({"model": "analytic.onnx", "name": "analytic-onnx",
  "latent_shape": [2, 4, 4],
  "inputs": {"latent": "x", "alpha_bar": "alpha_bar", "condition_latent": "cond"},
  "output": "eps"})";

// Hands each conditional query the condition latent the prior would: a constant field at the
// condition's data mean (the ONNX model reads its mean from it; zeros when unconditional).
class WithConditionLatents : public Denoiser {
 public:
  WithConditionLatents(const Denoiser& inner, std::vector<double> means) : inner_(inner) {
    for (double m : means) latents_.emplace_back(32, static_cast<float>(m));
  }
  absl::StatusOr<std::vector<float>> PredictNoise(const NoiseQuery& query) const override {
    NoiseQuery q = query;
    if (q.condition >= 0) q.condition_latent = &latents_.at(q.condition);
    return inner_.PredictNoise(q);
  }

 private:
  const Denoiser& inner_;
  std::vector<std::vector<float>> latents_;
};

class OnnxDenoiserTest : public ::testing::Test {
 protected:
  void SetUp() override {
    WriteModel(dir_.Sub("analytic.onnx"), "plain");
    WriteText(dir_.Sub("analytic.json"), kConfig);
  }
  absl::StatusOr<std::unique_ptr<OnnxDenoiser>> Load(const std::string& json) {
    absl::StatusOr<OnnxDenoiserConfig> config = ReadOnnxDenoiserConfig(json);
    if (!config.ok()) return config.status();
    return OnnxDenoiser::Load(*config, schedule_);
  }

  testing::ScopedTempDir dir_{"onnx_denoiser"};
  NoiseSchedule schedule_ = NoiseSchedule::ScaledLinear();
  std::vector<double> means_ = {0.1, 0.6};
  AnalyticDenoiser analytic_{schedule_, means_, 0.0, 0.5};
};

TEST_F(OnnxDenoiserTest, GivesTheSamplesOfTheInProcessAnalyticDenoiser) {
  auto onnx = Load(dir_.Sub("analytic.json"));
  ASSERT_TRUE(onnx.ok()) << onnx.status();
  EXPECT_EQ((*onnx)->latent_values(), 32);
  const WithConditionLatents conditioned(**onnx, means_);
  DdimOptions options;
  options.steps = 20;
  options.guidance = 2.0;  // the unconditional (zero condition) prediction too
  auto local = SampleDdim(analytic_, schedule_, 3, 32, {0, 1}, options);
  auto from_onnx = SampleDdim(conditioned, schedule_, 3, 32, {0, 1}, options);
  ASSERT_TRUE(local.ok() && from_onnx.ok()) << from_onnx.status();
  // float32 arithmetic in OpenCV against double in the analytic denoiser.
  double worst = 0;
  for (size_t n = 0; n < local->size(); ++n) {
    for (size_t j = 0; j < 32; ++j)
      worst = std::max(worst, std::abs(double((*local)[n][j]) - (*from_onnx)[n][j]));
  }
  EXPECT_LT(worst, 1e-4);
  EXPECT_GT(worst, 0.0);  // two implementations, not one called twice
}

TEST_F(OnnxDenoiserTest, ServedBehindTheDenoiserServiceItGivesTheSameSamplesBitForBit) {
  auto onnx = Load(dir_.Sub("analytic.json"));
  ASSERT_TRUE(onnx.ok()) << onnx.status();
  DenoiserService service(onnx->get(), "analytic-onnx", {2, 4, 4}, schedule_.size());
  rpc::ServerOptions server_options;
  server_options.listen = "127.0.0.1:0";
  auto server = rpc::Server::Start(server_options, {&service}, {"instascene.v1.Denoiser"});
  ASSERT_TRUE(server.ok()) << server.status();
  GrpcDenoiserOptions client_options;
  client_options.latent_shape = {2, 4, 4};
  GrpcDenoiser remote(rpc::Connect((*server)->address()), (*server)->address(), client_options);
  DdimOptions options;
  options.steps = 10;
  options.guidance = 2.0;
  auto local = SampleDdim(WithConditionLatents(**onnx, means_), schedule_, 2, 32, {0, 1}, options);
  auto over_grpc =
      SampleDdim(WithConditionLatents(remote, means_), schedule_, 2, 32, {0, 1}, options);
  ASSERT_TRUE(local.ok() && over_grpc.ok()) << over_grpc.status();
  EXPECT_EQ(*local, *over_grpc);
  (*server)->Drain(std::chrono::milliseconds(100));
}

TEST_F(OnnxDenoiserTest, MalformedConfigsAreRefusedNamingTheFileAndField) {
  EXPECT_EQ(Load(dir_.Sub("absent.json")).status().code(), absl::StatusCode::kNotFound);
  struct Case {
    std::string json, expected;
  } cases[] = {
      {"[1, 2]", "not a JSON object"},
      {R"({"model": "analytic.onnx", "output": "eps", "inputs": {"latent": "x"}})",
       "\"latent_shape\" must be [C, H, W]"},
      {R"({"model": "analytic.onnx", "output": "eps", "latent_shape": [2, 4, 0],
           "inputs": {"latent": "x"}})",
       "positive integers"},
      {R"({"model": "analytic.onnx", "output": "eps", "latent_shape": [64, 64, 64],
           "inputs": {"latent": "x"}})",
       "more than 65536 values"},
      {R"({"model": "analytic.onnx", "output": "eps", "latent_shape": [2, 4, 4],
           "inputs": {"latent": "x", "text_embedding": "e"}})",
       "unknown input \"text_embedding\""},
      {R"({"output": "eps", "latent_shape": [2, 4, 4], "inputs": {"latent": "x"}})",
       "\"model\" is missing"},
  };
  for (const Case& c : cases) {
    WriteText(dir_.Sub("bad.json"), c.json);
    const absl::Status s = Load(dir_.Sub("bad.json")).status();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << c.json;
    EXPECT_NE(s.message().find(dir_.Sub("bad.json")), std::string::npos) << s;
    EXPECT_NE(s.message().find(c.expected), std::string::npos) << s;
  }
}

TEST_F(OnnxDenoiserTest, AModelThatDoesNotMatchItsConfigFailsAtLoad) {
  WriteText(dir_.Sub("no_model.json"), R"({"model": "missing.onnx", "output": "eps",
    "latent_shape": [2, 4, 4], "inputs": {"latent": "x"}})");
  EXPECT_EQ(Load(dir_.Sub("no_model.json")).status().code(), absl::StatusCode::kNotFound);
  WriteText(dir_.Sub("not_onnx.onnx"), "these bytes are not a protobuf");
  WriteText(dir_.Sub("not_onnx.json"), R"({"model": "not_onnx.onnx", "output": "eps",
    "latent_shape": [2, 4, 4], "inputs": {"latent": "x"}})");
  absl::Status s = Load(dir_.Sub("not_onnx.json")).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition) << s;
  EXPECT_NE(s.message().find("not_onnx.onnx"), std::string::npos) << s;
  // An input name the model does not have.
  WriteText(dir_.Sub("wrong_name.json"), R"({"model": "analytic.onnx", "output": "eps",
    "latent_shape": [2, 4, 4], "inputs": {"latent": "noisy", "alpha_bar": "alpha_bar",
    "condition_latent": "cond"}})");
  s = Load(dir_.Sub("wrong_name.json")).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition) << s;
  // An output of the wrong size.
  WriteModel(dir_.Sub("short.onnx"), "short");
  WriteText(dir_.Sub("short.json"), R"({"model": "short.onnx", "output": "eps",
    "latent_shape": [2, 4, 4], "inputs": {"latent": "x", "alpha_bar": "alpha_bar",
    "condition_latent": "cond"}})");
  s = Load(dir_.Sub("short.json")).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  EXPECT_NE(s.message().find("has 1 values"), std::string::npos) << s;
}

TEST_F(OnnxDenoiserTest, ANonFiniteAnswerStopsTheSamplerNamingWhere) {
  WriteModel(dir_.Sub("nan.onnx"), "nan");
  WriteText(dir_.Sub("nan.json"), R"({"model": "nan.onnx", "output": "eps",
    "latent_shape": [2, 4, 4], "inputs": {"latent": "x", "alpha_bar": "alpha_bar",
    "condition_latent": "cond"}})");
  auto onnx = Load(dir_.Sub("nan.json"));
  ASSERT_TRUE(onnx.ok()) << onnx.status();
  auto samples = SampleDdim(**onnx, schedule_, 1, 32, {0}, DdimOptions{});
  EXPECT_EQ(samples.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(samples.status().message().find("not finite"), std::string::npos) << samples.status();
  const std::vector<float> wrong(5, 0.0f);
  EXPECT_EQ((*onnx)->PredictNoise(NoiseQuery{&wrong, 0, 0, 0}).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace instascene::generation::diffusion
