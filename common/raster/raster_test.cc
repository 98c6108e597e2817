#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "common/raster/projection.h"
#include "common/raster/rasterizer.h"
#include "common/raster/testing/reference_renderer.h"
#include "common/splat/sh.h"

namespace instascene {
namespace {

PinholeCamera FrontCamera(int width, int height, double focal) {
  PinholeCamera camera;
  camera.width = width;
  camera.height = height;
  camera.fx = camera.fy = focal;
  camera.cx = 0.5 * width;
  camera.cy = 0.5 * height;
  return camera;  // identity pose: looks down +z from the origin
}

// Random Gaussians in front of an identity camera, some behind it or near it.
GaussianCloud RandomScene(size_t n, int num_scales, int sh_degree, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  std::normal_distribution<float> normal;
  GaussianCloud cloud;
  cloud.num_scales = num_scales;
  cloud.sh_degree = sh_degree;
  cloud.Resize(n);
  for (size_t i = 0; i < n; ++i) {
    cloud.positions[3 * i] = 3.0f * uni(rng) - 1.5f;
    cloud.positions[3 * i + 1] = 2.2f * uni(rng) - 1.1f;
    cloud.positions[3 * i + 2] = i % 37 == 0 ? 0.1f * uni(rng) : 1.5f + 4.0f * uni(rng);
    for (int k = 0; k < num_scales; ++k)
      cloud.log_scales[num_scales * i + k] = -4.0f + 2.5f * uni(rng);
    for (int k = 0; k < 4; ++k) cloud.rotations[4 * i + k] = normal(rng);
    cloud.opacity_logits[i] = 2.0f * normal(rng);
    for (int k = 0; k < cloud.sh_stride(); ++k)
      cloud.sh[cloud.sh_stride() * i + k] = 0.5f * normal(rng);
  }
  return cloud;
}

std::vector<float> RandomFeatures(size_t n, int dim, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> normal;
  std::vector<float> f(n * dim);
  for (float& v : f) v = normal(rng);
  return f;
}

void ExpectNear(const std::vector<float>& got, const std::vector<float>& want, const char* what) {
  ASSERT_EQ(got.size(), want.size()) << what;
  int bad = 0;
  for (size_t i = 0; i < got.size(); ++i) {
    const float tol = 1e-5f * std::max(1.0f, std::abs(want[i]));
    if (!(std::abs(got[i] - want[i]) <= tol) && ++bad <= 5) {
      ADD_FAILURE() << what << "[" << i << "] = " << got[i] << ", reference " << want[i];
    }
  }
  EXPECT_EQ(bad, 0) << what;
}

RenderOptions AllOutputs(const std::vector<float>& features, int dim) {
  RenderOptions options;
  options.depth = true;
  options.normal = true;
  options.background[0] = 0.2f;
  options.background[1] = 0.5f;
  options.background[2] = 1.0f;
  options.features = features.data();
  options.feature_dim = dim;
  options.trace.enabled = true;
  options.trace.transmittance = true;
  return options;
}

class RasterVsReference : public ::testing::TestWithParam<std::tuple<int, int>> {};

TEST_P(RasterVsReference, RandomScenesMatchBruteForce) {
  const auto [num_scales, degree] = GetParam();
  for (uint32_t seed = 1; seed <= 3; ++seed) {
    GaussianCloud cloud = RandomScene(400, num_scales, degree, seed * 7 + degree);
    std::vector<float> features = RandomFeatures(cloud.size(), 3, seed);
    PinholeCamera camera = FrontCamera(70, 50, 60.0);
    RenderOptions options = AllOutputs(features, 3);
    absl::StatusOr<RenderResult> fast = Render(cloud, camera, options);
    ASSERT_TRUE(fast.ok()) << fast.status();
    RenderResult ref = testing::ReferenceRender(cloud, camera, options);
    ExpectNear(fast->color, ref.color, "color");
    ExpectNear(fast->alpha, ref.alpha, "alpha");
    ExpectNear(fast->depth, ref.depth, "depth");
    ExpectNear(fast->median_depth, ref.median_depth, "median_depth");
    ExpectNear(fast->normal, ref.normal, "normal");
    ExpectNear(fast->features, ref.features, "features");
    EXPECT_EQ(fast->num_contributors, ref.num_contributors);
    EXPECT_EQ(fast->visible, ref.visible);
    ASSERT_EQ(fast->trace.pixels, ref.trace.pixels);
    ASSERT_EQ(fast->trace.offsets, ref.trace.offsets);
    for (size_t e = 0; e < ref.trace.entries.size(); ++e) {
      ASSERT_EQ(fast->trace.entries[e].gaussian, ref.trace.entries[e].gaussian) << e;
      ASSERT_NEAR(fast->trace.entries[e].weight, ref.trace.entries[e].weight, 1e-5);
      ASSERT_NEAR(fast->trace.transmittance[e], ref.trace.transmittance[e], 1e-5);
    }
    // Without transmittance the full trace takes the 8-lane append path: the same lists.
    RenderOptions plain_trace = options;
    plain_trace.trace.transmittance = false;
    absl::StatusOr<RenderResult> vector_path = Render(cloud, camera, plain_trace);
    ASSERT_TRUE(vector_path.ok());
    ASSERT_EQ(vector_path->trace.offsets, fast->trace.offsets);
    EXPECT_TRUE(vector_path->trace.transmittance.empty());
    for (size_t e = 0; e < fast->trace.entries.size(); ++e) {
      ASSERT_EQ(vector_path->trace.entries[e].gaussian, fast->trace.entries[e].gaussian) << e;
      ASSERT_EQ(vector_path->trace.entries[e].weight, fast->trace.entries[e].weight) << e;
    }
    // ...and with a minimum weight it keeps exactly the entries above it, in order.
    plain_trace.trace.min_weight = 0.1f;
    absl::StatusOr<RenderResult> heavy = Render(cloud, camera, plain_trace);
    ASSERT_TRUE(heavy.ok());
    for (size_t px = 0; px < fast->trace.num_pixels(); ++px) {
      std::vector<std::pair<uint32_t, float>> want, got;
      for (uint64_t k = fast->trace.offsets[px]; k < fast->trace.offsets[px + 1]; ++k) {
        if (fast->trace.entries[k].weight > 0.1f)
          want.emplace_back(fast->trace.entries[k].gaussian, fast->trace.entries[k].weight);
      }
      for (uint64_t k = heavy->trace.offsets[px]; k < heavy->trace.offsets[px + 1]; ++k)
        got.emplace_back(heavy->trace.entries[k].gaussian, heavy->trace.entries[k].weight);
      ASSERT_EQ(got, want) << px;
    }
    EXPECT_GT(fast->stats.blended_fragments, 1000u);  // the scene is not trivially empty
  }
}

INSTANTIATE_TEST_SUITE_P(ModelsAndShDegrees, RasterVsReference,
                         ::testing::Combine(::testing::Values(2, 3),
                                            ::testing::Values(0, 1, 2, 3)));

TEST(Raster, SingleFrontalSurfelMatchesClosedForm) {
  // A surfel facing the camera on the optical axis, centred on pixel (16, 16) of a 33x33 image.
  GaussianCloud cloud;
  cloud.num_scales = 2;
  cloud.Resize(1);
  const float z0 = 4.0f, sigma = 0.1f, opacity = 0.8f, focal = 50.0f;
  cloud.positions = {0, 0, z0};
  cloud.log_scales = {std::log(sigma), std::log(sigma)};
  cloud.opacity_logits = {std::log(opacity / (1 - opacity))};
  cloud.sh = {RgbToSh0(0.25f), RgbToSh0(0.5f), RgbToSh0(0.75f)};
  RenderOptions options;
  options.depth = true;
  options.normal = true;
  absl::StatusOr<RenderResult> r = Render(cloud, FrontCamera(33, 33, focal), options);
  ASSERT_TRUE(r.ok()) << r.status();
  for (int dx : {0, 1, 2, 3, 5, 8}) {
    const size_t pix = 16 * 33 + 16 + dx;
    const double u = dx * z0 / (focal * sigma);
    const double g = std::max(std::exp(-0.5 * u * u), std::exp(-1.0 * dx * dx));
    const double alpha = opacity * g < 1.0 / 255 ? 0.0 : opacity * g;
    EXPECT_NEAR(r->alpha[pix], alpha, 1e-6) << dx;
    EXPECT_NEAR(r->color[3 * pix + 2], 0.75 * alpha, 1e-6) << dx;
    if (alpha > 0) {
      EXPECT_NEAR(r->depth[pix], z0, 1e-5);
      EXPECT_NEAR(r->median_depth[pix], z0, 1e-5);
      EXPECT_NEAR(r->normal[3 * pix + 2], -alpha, 1e-6);  // faces the camera
    }
  }
}

TEST(Raster, SingleIsotropicEllipsoidMatchesEwa) {
  GaussianCloud cloud;
  cloud.num_scales = 3;
  cloud.Resize(1);
  const float z0 = 5.0f, sigma = 0.08f, opacity = 0.9f, focal = 60.0f;
  cloud.positions = {0, 0, z0};
  cloud.log_scales.assign(3, std::log(sigma));
  cloud.opacity_logits = {std::log(opacity / (1 - opacity))};
  absl::StatusOr<RenderResult> r = Render(cloud, FrontCamera(33, 33, focal), RenderOptions{});
  ASSERT_TRUE(r.ok()) << r.status();
  const double var_px = std::pow(focal * sigma / z0, 2) + 0.3;
  for (int dy : {0, 1, 2, 4}) {
    const size_t pix = (16 + dy) * 33 + 16;
    const double alpha = opacity * std::exp(-0.5 * dy * dy / var_px);
    EXPECT_NEAR(r->alpha[pix], alpha < 1.0 / 255 ? 0.0 : alpha, 1e-6) << dy;
  }
}

TEST(Raster, OpaqueStackStopsAtTransmittanceFloor) {
  // 5 stacked surfels with alpha 0.95 at the centre pixel: T goes 1 -> 0.05 -> 0.0025 -> 1.25e-4
  // (still >= 1e-4: blended) -> 6.25e-6 (< 1e-4: the fourth is not blended and the pixel stops).
  GaussianCloud cloud;
  cloud.num_scales = 2;
  cloud.Resize(5);
  for (int i = 0; i < 5; ++i) {
    cloud.positions[3 * i + 2] = 2.0f + 0.1f * i;
    cloud.log_scales[2 * i] = cloud.log_scales[2 * i + 1] = std::log(1.0f);
    cloud.opacity_logits[i] = std::log(0.95f / 0.05f);
  }
  RenderOptions options;
  options.trace.enabled = true;
  options.trace.pixels = {16 * 33 + 16};
  options.trace.transmittance = true;
  absl::StatusOr<RenderResult> r = Render(cloud, FrontCamera(33, 33, 50.0), options);
  ASSERT_TRUE(r.ok());
  ASSERT_EQ(r->trace.entries.size(), 3u);
  for (uint32_t k = 0; k < 3; ++k) EXPECT_EQ(r->trace.entries[k].gaussian, k);
  EXPECT_NEAR(r->trace.transmittance[2], 0.0025f, 1e-7);
  EXPECT_NEAR(r->trace.entries[2].weight, 0.95f * 0.0025f, 1e-7);
  EXPECT_NEAR(r->alpha[16 * 33 + 16], 1.0f - 1.25e-4f, 1e-6);
}

TEST(Raster, TraceReproducesFeatureImageExactly) {
  GaussianCloud cloud = RandomScene(600, 2, 1, 99);
  const int dim = 5;
  std::vector<float> features = RandomFeatures(cloud.size(), dim, 4);
  RenderOptions options = AllOutputs(features, dim);
  absl::StatusOr<RenderResult> r = Render(cloud, FrontCamera(64, 48, 55.0), options);
  ASSERT_TRUE(r.ok());
  ASSERT_EQ(r->trace.num_pixels(), 64u * 48u);
  for (size_t p = 0; p < r->trace.num_pixels(); ++p) {
    float e[dim] = {0, 0, 0, 0, 0};
    for (uint64_t k = r->trace.offsets[p]; k < r->trace.offsets[p + 1]; ++k) {
      const Contribution& c = r->trace.entries[k];
      for (int d = 0; d < dim; ++d) e[d] += c.weight * features[c.gaussian * dim + d];
    }
    for (int d = 0; d < dim; ++d) ASSERT_EQ(e[d], r->features[p * dim + d]) << p << " " << d;
  }
}

TEST(Raster, IdenticalForAnyThreadCount) {
  GaussianCloud cloud = RandomScene(3000, 2, 2, 5);
  std::vector<float> features = RandomFeatures(cloud.size(), 4, 6);
  RenderOptions options = AllOutputs(features, 4);
  options.num_threads = 1;
  absl::StatusOr<RenderResult> one = Render(cloud, FrontCamera(96, 80, 70.0), options);
  options.num_threads = 2;
  absl::StatusOr<RenderResult> two = Render(cloud, FrontCamera(96, 80, 70.0), options);
  options.num_threads = 4;
  RasterWorkspace workspace;  // a reused workspace must not leak state between renders
  options.workspace = &workspace;
  ASSERT_TRUE(Render(RandomScene(500, 2, 2, 77), FrontCamera(40, 30, 30.0), options).ok());
  absl::StatusOr<RenderResult> four = Render(cloud, FrontCamera(96, 80, 70.0), options);
  ASSERT_TRUE(one.ok() && two.ok() && four.ok());
  for (const RenderResult* other : {&*two, &*four}) {
    EXPECT_EQ(one->color, other->color);
    EXPECT_EQ(one->depth, other->depth);
    EXPECT_EQ(one->median_depth, other->median_depth);
    EXPECT_EQ(one->normal, other->normal);
    EXPECT_EQ(one->features, other->features);
    EXPECT_EQ(one->trace.offsets, other->trace.offsets);
    ASSERT_EQ(one->trace.entries.size(), other->trace.entries.size());
    for (size_t e = 0; e < one->trace.entries.size(); ++e) {
      ASSERT_EQ(one->trace.entries[e].gaussian, other->trace.entries[e].gaussian);
      ASSERT_EQ(one->trace.entries[e].weight, other->trace.entries[e].weight);
    }
  }
}

// The batched (4-lane) surfel projection gives every Gaussian the same bits however the batch
// is cut, so a render cannot depend on how the Gaussians are split among threads.
TEST(Raster, SurfelProjectionDoesNotDependOnBatching) {
  const GaussianCloud cloud = RandomScene(203, 2, 3, 21);
  const ProjectionParams params =
      MakeProjectionParams(FrontCamera(96, 64, 80.0), RenderOptions{}, cloud.sh_degree);
  std::vector<ProjectedSplat> whole(cloud.size());
  std::vector<uint8_t> whole_visible(cloud.size());
  ProjectSurfels(cloud, 0, cloud.size(), params, whole.data(), whole_visible.data());
  int visible = 0;
  for (size_t first = 0; first < cloud.size();) {
    const size_t count = std::min<size_t>(1 + first % 7, cloud.size() - first);
    std::vector<ProjectedSplat> part(count);
    std::vector<uint8_t> part_visible(count);
    ProjectSurfels(cloud, first, count, params, part.data(), part_visible.data());
    for (size_t k = 0; k < count; ++k) {
      ASSERT_EQ(part_visible[k], whole_visible[first + k]) << first + k;
      if (!part_visible[k]) continue;
      ++visible;
      EXPECT_EQ(std::memcmp(&part[k], &whole[first + k], sizeof(ProjectedSplat)), 0) << first + k;
    }
    first += count;
  }
  EXPECT_GT(visible, 100);
}

TEST(Raster, PixelSubsetAndMinWeightFilterTheFullTrace) {
  GaussianCloud cloud = RandomScene(800, 2, 0, 8);
  PinholeCamera camera = FrontCamera(50, 40, 45.0);
  RenderOptions full;
  full.trace.enabled = true;
  absl::StatusOr<RenderResult> all = Render(cloud, camera, full);
  RenderOptions subset = full;
  subset.trace.pixels = {0, 17, 333, 1000, 1999};
  subset.trace.min_weight = 0.1f;
  absl::StatusOr<RenderResult> some = Render(cloud, camera, subset);
  ASSERT_TRUE(all.ok() && some.ok());
  ASSERT_EQ(some->trace.pixels, subset.trace.pixels);
  for (size_t i = 0; i < subset.trace.pixels.size(); ++i) {
    const uint32_t pix = subset.trace.pixels[i];
    std::vector<uint32_t> want, got;
    for (uint64_t k = all->trace.offsets[pix]; k < all->trace.offsets[pix + 1]; ++k) {
      if (all->trace.entries[k].weight > 0.1f) want.push_back(all->trace.entries[k].gaussian);
    }
    for (uint64_t k = some->trace.offsets[i]; k < some->trace.offsets[i + 1]; ++k) {
      got.push_back(some->trace.entries[k].gaussian);
    }
    EXPECT_EQ(got, want) << pix;
  }
}

TEST(Raster, RejectsBadRequests) {
  GaussianCloud cloud = RandomScene(10, 2, 0, 1);
  RenderOptions options;
  options.model = SplatModel::kEllipsoid3d;
  EXPECT_EQ(Render(cloud, FrontCamera(8, 8, 10), options).status().code(),
            absl::StatusCode::kInvalidArgument);
  options.model = SplatModel::kAuto;
  options.trace.enabled = true;
  options.trace.pixels = {5, 3};
  EXPECT_FALSE(Render(cloud, FrontCamera(8, 8, 10), options).ok());
  options.trace.pixels = {64};
  EXPECT_FALSE(Render(cloud, FrontCamera(8, 8, 10), options).ok());
  options.trace.pixels = {};
  options.feature_dim = 3;
  EXPECT_FALSE(Render(cloud, FrontCamera(8, 8, 10), options).ok());
  EXPECT_FALSE(Render(cloud, FrontCamera(0, 8, 10), RenderOptions{}).ok());
}

}  // namespace
}  // namespace instascene
