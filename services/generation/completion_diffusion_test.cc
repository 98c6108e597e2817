// The completion with the diffusion prior (ALGORITHM.md 7.7): through a loopback Denoiser
// service, its replacement schedule and warp space, and the worker's denoiser setting.
#include "services/generation/completion.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "common/geometry/camera.h"
#include "common/mesh/ray_caster.h"
#include "common/mesh/surfel_mesh.h"
#include "common/rpc/server.h"
#include "common/synth/primitives.h"
#include "common/synth/surfels.h"
#include "services/generation/diffusion/analytic_denoiser.h"
#include "services/generation/diffusion/grpc_denoiser.h"
#include "services/generation/diffusion/latent_codec.h"
#include "services/generation/stage.h"
#include "services/generation/testing/partial_objects.h"

namespace instascene::generation {
namespace {

using namespace testing;  // NOLINT(build/namespaces): the test scenes

// A partly seen bottle with a wall behind it (x = -0.12): the ring views from that side see it
// occluded, so they are unknown and become the diffusion sampler's targets.
PartialObject BottleBeforeAWall() {
  PartialObject scene = MakePartialObject(Bottle(), 2500, 19);
  TriangleMesh wall = MakeRectangle(0.6f, 0.5f, 6, 5);
  for (auto& v : wall.vertices) v = Eigen::Vector3f(-0.12f, v.x(), v.y() + 0.25f);
  std::mt19937_64 rng(3);
  AppendSurfels(wall, 3000, Appearance{}, SurfelSampling{}, rng, &scene.cloud);
  scene.labels.resize(scene.cloud.size(), 0);
  return scene;
}

// The analytic denoiser (data mean 0.2 under every condition view, 0 unconditional, stddev 0.4)
// behind a loopback Denoiser service that takes timesteps below `timesteps`.
class LoopbackAnalyticDenoiser {
 public:
  explicit LoopbackAnalyticDenoiser(int timesteps = 1000)
      : service_(&analytic_, "analytic-gaussian", {4, 32, 32}, timesteps) {
    rpc::ServerOptions options;
    options.listen = "127.0.0.1:0";
    auto server = rpc::Server::Start(options, {&service_}, {"instascene.v1.Denoiser"});
    EXPECT_TRUE(server.ok()) << server.status();
    if (server.ok()) server_ = std::move(*server);
  }
  ~LoopbackAnalyticDenoiser() {
    if (server_) server_->Drain(std::chrono::milliseconds(100));
  }
  bool ok() const { return server_ != nullptr; }
  std::string uri() const { return "grpc://" + server_->address(); }

 private:
  diffusion::AnalyticDenoiser analytic_{diffusion::NoiseSchedule::ScaledLinear(),
                                        std::vector<double>(16, 0.2), 0.0, 0.4};
  diffusion::DenoiserService service_;
  std::unique_ptr<rpc::Server> server_;
};

// The diffusion prior through a loopback Denoiser service (the analytic denoiser: it proves the
// plumbing, not the images): it generates one image per unknown ring view, which the refinement
// then fits; an unreachable or misbehaving denoiser fails the object with a message naming it.
TEST(Completion, DiffusionPriorThroughADenoiserService) {
  const LoopbackAnalyticDenoiser denoiser;
  ASSERT_TRUE(denoiser.ok());
  const PartialObject scene = BottleBeforeAWall();
  ASSERT_GT(std::count(scene.labels.begin(), scene.labels.end(), 0), 0);  // the wall is there
  CompletionOptions options;
  options.meshing.size_px = 64;
  options.prior = "diffusion";
  options.denoiser = denoiser.uri();
  options.refinement.iterations = 5;
  auto done = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  ASSERT_TRUE(done.ok()) << done.status();
  const int unknown = done->manifest["unknown_views"].get<int>();
  ASSERT_GT(unknown, 0);
  EXPECT_EQ(done->manifest["prior"], "diffusion");
  EXPECT_EQ(static_cast<int>(done->prior.generated.size()), unknown);
  for (const ViewImages& v : done->prior.generated) {
    EXPECT_EQ(v.rgb.size(), static_cast<size_t>(3) * v.camera.width * v.camera.height);
  }
  const int64_t warped = done->prior.report["warped_latent_pixels"].get<int64_t>();
  EXPECT_GT(warped, 0);
  // Depth and mask come from the latent's depth channel: in every warped cell the decoded depth
  // is the instance hit's along the latent grid's ray through the cell, exactly
  // (replacement runs to the last step); masked pixels have a depth, others none.
  auto mesh = RayCaster::Create(SurfelDiscs(done->raw, {}, SurfelDiscOptions{}));
  ASSERT_TRUE(mesh.ok());
  int64_t exact = 0, object_pixels = 0;
  for (const ViewImages& v : done->prior.generated) {
    const size_t pixels = static_cast<size_t>(v.camera.width) * v.camera.height;
    ASSERT_EQ(v.depth.size(), pixels);
    ASSERT_EQ(v.mask.size(), pixels);
    for (size_t i = 0; i < pixels; ++i) {
      EXPECT_EQ(v.mask[i] != 0, v.depth[i] > 0) << i;
      object_pixels += v.mask[i];
    }
    const int n = 32, step = v.camera.width / n;
    const PinholeCamera grid = v.camera.Scaled(static_cast<double>(n) / v.camera.width);
    const Eigen::Vector3f eye = v.camera.CenterInWorld().cast<float>();
    const Eigen::Vector3d axis = v.camera.camera_from_world.rotation.row(2).transpose();
    for (int cy = 0; cy < n; ++cy) {
      for (int cx = 0; cx < n; ++cx) {
        const int x = cx * step + step / 2, y = cy * step + step / 2;
        const Eigen::Vector3d dir = grid.PixelRayInWorld(cx, cy);
        const RayHit hit = (*mesh)->Cast(eye, dir.cast<float>());
        const size_t i = static_cast<size_t>(y) * v.camera.width + x;
        exact += hit.hit && v.mask[i] && std::abs(v.depth[i] - hit.distance * dir.dot(axis)) < 1e-4;
      }
    }
  }
  EXPECT_GE(exact, warped);
  EXPECT_EQ(done->prior.report["generated_object_pixels"].get<int64_t>(), object_pixels);
  // The unseen-region estimate (7.8) pins what the real views saw empty to the background and
  // leaves the rest (space behind the wall, the bottle's unseen side) to the sampler.
  EXPECT_EQ(done->prior.report["unseen_mask"], true);
  EXPECT_GT(done->prior.report["background_cells"].get<int64_t>(), 0);
  EXPECT_GT(done->prior.report["generated_cells"].get<int64_t>(), 0);
  EXPECT_EQ(done->manifest["refinement"]["generated_from"], "the prior's images");
  EXPECT_EQ(done->object.size(), done->raw.size());  // this prior adds images, not surfels

  options.denoiser = "grpc://127.0.0.1:1";  // nothing listens there
  auto unreachable = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  EXPECT_EQ(unreachable.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(unreachable.status().message().find("denoiser"), std::string::npos);
  const LoopbackAnalyticDenoiser wrong(10);  // refuses timesteps >= 10
  ASSERT_TRUE(wrong.ok());
  options.denoiser = wrong.uri();
  auto refused = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("timestep"), std::string::npos) << refused.status();
  options.denoiser = "onnx:absent/model.json";
  auto no_config = CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  EXPECT_EQ(no_config.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(no_config.status().message().find("absent/model.json"), std::string::npos);
}

// The replacement schedule and the warp space (ALGORITHM.md 7.7's open choices) as settings:
// replacing to the last step leaves the known cells exactly the warped known content; never
// replacing lets them drift; a pixel-space warp finds known cells too.
TEST(Completion, DiffusionReplacementScheduleAndWarpSpace) {
  const LoopbackAnalyticDenoiser denoiser;
  ASSERT_TRUE(denoiser.ok());
  const PartialObject scene = BottleBeforeAWall();
  CompletionOptions options;
  options.meshing.size_px = 64;
  options.prior = "diffusion";
  options.denoiser = denoiser.uri();
  auto run = [&](double fraction, const std::string& warp) {
    options.diffusion.replace_fraction = fraction;
    options.diffusion.warp = warp;
    return CompleteObject(scene.cameras, scene.cloud, scene.labels, 1, options);
  };
  auto every = run(1.0, "latent");
  ASSERT_TRUE(every.ok()) << every.status();
  ASSERT_GT(every->prior.report["warped_latent_pixels"].get<int64_t>(), 0);
  EXPECT_EQ(every->prior.report["known_cells_drift"].get<double>(), 0.0);
  auto never = run(0.0, "latent");
  ASSERT_TRUE(never.ok()) << never.status();
  EXPECT_GT(never->prior.report["known_cells_drift"].get<double>(), 0.05);
  auto half = run(0.5, "latent");
  ASSERT_TRUE(half.ok()) << half.status();
  EXPECT_GT(half->prior.report["known_cells_drift"].get<double>(), 0.0);
  EXPECT_EQ(half->prior.report["replace_fraction"].get<double>(), 0.5);
  auto pixel = run(1.0, "pixel");
  ASSERT_TRUE(pixel.ok()) << pixel.status();
  EXPECT_EQ(pixel->prior.report["warp"], "pixel");
  EXPECT_GT(pixel->prior.report["warped_latent_pixels"].get<int64_t>(), 0);
  EXPECT_EQ(pixel->prior.report["known_cells_drift"].get<double>(), 0.0);
  options.diffusion.unseen_mask = false;  // every cell not known is generated
  auto unmasked = run(1.0, "latent");
  ASSERT_TRUE(unmasked.ok()) << unmasked.status();
  EXPECT_EQ(unmasked->prior.report["unseen_mask"], false);
  EXPECT_EQ(unmasked->prior.report["background_cells"].get<int64_t>(), 0);
  EXPECT_GT(unmasked->prior.report["generated_cells"].get<int64_t>(),
            every->prior.report["generated_cells"].get<int64_t>());
  options.diffusion.unseen_mask = true;
  // The codec (VAE) interface: every known view encoded once (and the white background once),
  // every generated one decoded once.
  struct Counting : diffusion::LatentCodec {
    diffusion::IdentityCodec identity{32};
    mutable std::atomic<int> encoded{0}, decoded{0};
    std::string name() const override { return "counting identity"; }
    int latent_values() const override { return identity.latent_values(); }
    absl::StatusOr<std::vector<float>> Encode(const std::vector<float>& rgb, int w,
                                              int h) const override {
      ++encoded;
      return identity.Encode(rgb, w, h);
    }
    absl::StatusOr<std::vector<float>> Decode(const std::vector<float>& latent, int w,
                                              int h) const override {
      ++decoded;
      return identity.Decode(latent, w, h);
    }
  };
  auto counting = std::make_shared<Counting>();
  options.diffusion.codec = counting;
  auto coded = run(1.0, "latent");
  ASSERT_TRUE(coded.ok()) << coded.status();
  EXPECT_EQ(coded->prior.report["vae"], "counting identity");
  EXPECT_EQ(counting->encoded.load(),
            static_cast<int>(coded->ring.size()) + 1 - coded->manifest["unknown_views"].get<int>());
  EXPECT_EQ(counting->decoded.load(), coded->manifest["unknown_views"].get<int>());
  // A four-channel codec (a Stable Diffusion VAE's latent depth): the denoiser sees [5, 32, 32]
  // (MVD-Fusion's layout), both warps move all four channels.
  struct FourChannels : diffusion::LatentCodec {
    diffusion::IdentityCodec identity{32};
    std::string name() const override { return "identity + luminance"; }
    int latent_values() const override { return 4 * 32 * 32; }
    absl::StatusOr<std::vector<float>> Encode(const std::vector<float>& rgb, int w,
                                              int h) const override {
      absl::StatusOr<std::vector<float>> encoded = identity.Encode(rgb, w, h);
      if (!encoded.ok()) return encoded.status();
      std::vector<float> latent = std::move(*encoded);
      for (int cell = 0; cell < 32 * 32; ++cell)
        latent.push_back((latent[cell] + latent[1024 + cell] + latent[2048 + cell]) / 3);
      return latent;
    }
    absl::StatusOr<std::vector<float>> Decode(const std::vector<float>& latent, int w,
                                              int h) const override {
      return identity.Decode(std::vector<float>(latent.begin(), latent.begin() + 3 * 1024), w, h);
    }
  };
  options.diffusion.codec = std::make_shared<FourChannels>();
  for (const char* warp : {"latent", "pixel"}) {
    auto four = run(1.0, warp);
    ASSERT_TRUE(four.ok()) << four.status();
    EXPECT_EQ(four->prior.report["latent_shape"], nlohmann::json({5, 32, 32})) << warp;
    EXPECT_EQ(four->prior.report["known_cells_drift"].get<double>(), 0.0) << warp;
    EXPECT_GT(four->prior.report["warped_latent_pixels"].get<int64_t>(), 0) << warp;
  }
  options.diffusion.codec = std::make_shared<diffusion::IdentityCodec>(16);  // 3 x 16²: refused
  EXPECT_EQ(run(1.0, "latent").status().code(), absl::StatusCode::kInvalidArgument);
  options.diffusion.codec = nullptr;
  EXPECT_EQ(run(1.0, "voxel").status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(run(1.5, "latent").status().code(), absl::StatusCode::kInvalidArgument);
}

// The complete stage takes the denoiser from the worker's settings, never from the job.
TEST(CompleteStage, DiffusionNeedsAWorkerWithADenoiser) {
  const pipeline::StageDefinition stage = CompleteStage();
  pipeline::StageContext context;
  context.parameters = {{"prior", "diffusion"}};
  auto without = stage.run(context);
  EXPECT_EQ(without.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(without.status().message().find("--denoiser grpc://HOST:PORT"), std::string::npos);
  context.settings["denoiser"] = "grpc://127.0.0.1:1";
  auto with = stage.run(context);  // past the check: this context has no segment input
  EXPECT_NE(with.status().code(), absl::StatusCode::kFailedPrecondition) << with.status();
  EXPECT_NE(with.status().message().find("segment"), std::string::npos) << with.status();
}

}  // namespace
}  // namespace instascene::generation
