#include "services/generation/normal_consistency.h"

#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

namespace instascene::generation {
namespace {

// A 24x18 camera, turned away from the world axes (the loss mixes frames) and with an off-centre
// principal point.
PinholeCamera Camera() {
  PinholeCamera c;
  c.width = 24;
  c.height = 18;
  c.fx = 30;
  c.fy = 28;
  c.cx = 11.3;
  c.cy = 9.6;
  c.camera_from_world.rotation =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.3, -1.0, 0.4).normalized()).toRotationMatrix();
  c.camera_from_world.translation = Eigen::Vector3d(0.2, -0.1, 0.5);
  return c;
}

// Camera z of the plane through (0, 0, 2) (camera frame) with unit normal n, at pixel (x, y).
double PlaneDepth(const PinholeCamera& c, const Eigen::Vector3d& n, int x, int y) {
  const Eigen::Vector3d ray((x + 0.5 - c.cx) / c.fx, (y + 0.5 - c.cy) / c.fy, 1.0);
  return n.dot(Eigen::Vector3d(0, 0, 2)) / n.dot(ray);
}

// A rendered normal that agrees with the depth map's surface gives 1 - alpha; the surface normal
// faces the camera, as the rasteriser's normals do (a reversed one gives 1 + alpha).
TEST(NormalConsistency, APlaneWithItsOwnNormalGivesOneMinusAlpha) {
  const PinholeCamera c = Camera();
  const Eigen::Vector3d n_cam = Eigen::Vector3d(0.3, -0.2, -1.0).normalized();  // faces the camera
  const size_t pixels = size_t(c.width) * c.height;
  std::vector<float> depth(pixels), alpha(pixels, 0.8f), normal(3 * pixels), reversed(3 * pixels);
  const Eigen::Vector3d n_world = c.camera_from_world.rotation.transpose() * n_cam;
  for (int y = 0; y < c.height; ++y) {
    for (int x = 0; x < c.width; ++x) {
      const size_t i = size_t(y) * c.width + x;
      depth[i] = static_cast<float>(PlaneDepth(c, n_cam, x, y));
      for (int k = 0; k < 3; ++k) {
        normal[3 * i + k] = static_cast<float>(n_world[k]);
        reversed[3 * i + k] = -normal[3 * i + k];
      }
    }
  }
  std::vector<uint8_t> interior(pixels, 0);  // border pixels have no surface normal
  for (int y = 1; y + 1 < c.height; ++y) {
    for (int x = 1; x + 1 < c.width; ++x) interior[size_t(y) * c.width + x] = 1;
  }
  std::vector<float> dn(3 * pixels, 0.0f), dd(pixels, 0.0f);
  EXPECT_NEAR(*NormalConsistency(normal, depth, alpha, interior, c, 1.0, &dn, &dd), 0.2, 1e-5);
  EXPECT_NEAR(*NormalConsistency(reversed, depth, alpha, interior, c, 1.0, &dn, &dd), 1.8, 1e-5);
  const double inner = double(c.width - 2) * (c.height - 2);  // the border's pixels count 1
  EXPECT_NEAR(*NormalConsistency(normal, depth, alpha, {}, c, 1.0, &dn, &dd),
              (0.2 * inner + (pixels - inner)) / pixels, 1e-5);
  EXPECT_EQ(
      *NormalConsistency(normal, depth, alpha, std::vector<uint8_t>(pixels, 0), c, 1.0, &dn, &dd),
      0.0);
}

// Central differences in double for the normal and depth of probe pixels, on a curved depth map
// with holes (depth 0: their neighbours have no surface normal) and a partial mask.
TEST(NormalConsistency, MatchesFiniteDifferences) {
  const PinholeCamera c = Camera();
  const size_t pixels = size_t(c.width) * c.height;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<float> depth(pixels), alpha(pixels), normal(3 * pixels);
  std::vector<uint8_t> mask(pixels);
  for (int y = 0; y < c.height; ++y) {
    for (int x = 0; x < c.width; ++x) {
      const size_t i = size_t(y) * c.width + x;
      depth[i] = static_cast<float>(2.0 + 0.3 * std::sin(0.4 * x) * std::cos(0.5 * y) + 0.02 * x);
      alpha[i] = 0.6f + 0.4f * std::abs(u(rng));
      for (int k = 0; k < 3; ++k) normal[3 * i + k] = u(rng);
      mask[i] = (x + 2 * y) % 5 != 0;
    }
  }
  depth[5 * c.width + 7] = 0.0f;  // a hole
  auto loss = [&](const std::vector<float>& n, const std::vector<float>& d, std::vector<float>* gn,
                  std::vector<float>* gd) {
    return *NormalConsistency(n, d, alpha, mask, c, 1.0, gn, gd);
  };
  std::vector<float> gn(3 * pixels, 0.0f), gd(pixels, 0.0f);
  loss(normal, depth, &gn, &gd);
  std::vector<float> scratch_n(3 * pixels), scratch_d(pixels);
  double worst_normal = 0, worst_depth = 0;
  int nonzero = 0;
  for (size_t i = c.width + 1; i + c.width + 1 < pixels; i += 5) {
    if (i == size_t(5 * c.width + 7)) continue;  // moving a hole off 0 is a step
    const double eps = 1e-3;
    auto central = [&](std::vector<float>* values, size_t k) {
      const float keep = (*values)[k];
      (*values)[k] = static_cast<float>(keep + eps);
      const double plus = loss(normal, depth, &scratch_n, &scratch_d);
      (*values)[k] = static_cast<float>(keep - eps);
      const double minus = loss(normal, depth, &scratch_n, &scratch_d);
      (*values)[k] = keep;
      return (plus - minus) / (2 * eps);
    };
    const double numeric_d = central(&depth, i);
    worst_depth =
        std::max(worst_depth, std::abs(numeric_d - gd[i]) / std::max(1e-3, std::abs(numeric_d)));
    const double numeric_n = central(&normal, 3 * i + i % 3);
    worst_normal = std::max(worst_normal, std::abs(numeric_n - gn[3 * i + i % 3]) /
                                              std::max(1e-3, std::abs(numeric_n)));
    nonzero += gd[i] != 0.0f;
  }
  std::printf("normal consistency vs finite differences: normal %.2e depth %.2e\n", worst_normal,
              worst_depth);
  EXPECT_GT(nonzero, 20);
  EXPECT_LT(worst_normal, 1e-2);
  EXPECT_LT(worst_depth, 1e-2);
}

// Buffers of another size than the camera's image are refused, naming the buffer, and nothing
// is written into the gradients.
TEST(NormalConsistency, RefusesBuffersOfTheWrongSize) {
  const PinholeCamera c = Camera();
  const size_t pixels = size_t(c.width) * c.height;
  const std::vector<float> normal(3 * pixels, 0.5f), depth(pixels, 2.0f), alpha(pixels, 1.0f);
  std::vector<float> dn(3 * pixels, 0.0f), dd(pixels, 0.0f);
  auto refused = [&](const absl::StatusOr<double>& r, const std::string& name) {
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument) << name;
    EXPECT_NE(r.status().message().find(name + " has"), std::string::npos) << r.status();
  };
  refused(NormalConsistency(std::vector<float>(pixels), depth, alpha, {}, c, 1.0, &dn, &dd),
          "normal");
  refused(NormalConsistency(normal, std::vector<float>(pixels - 1), alpha, {}, c, 1.0, &dn, &dd),
          "depth");
  refused(NormalConsistency(normal, depth, {}, {}, c, 1.0, &dn, &dd), "alpha");
  refused(NormalConsistency(normal, depth, alpha, std::vector<uint8_t>(3), c, 1.0, &dn, &dd),
          "mask");
  std::vector<float> short_dd(pixels / 2, 0.0f);
  refused(NormalConsistency(normal, depth, alpha, {}, c, 1.0, &dn, &short_dd), "d_depth");
  EXPECT_FALSE(NormalConsistency(normal, depth, alpha, {}, c, 1.0, nullptr, &dd).ok());
  for (float v : dn) ASSERT_EQ(v, 0.0f);
  for (float v : dd) ASSERT_EQ(v, 0.0f);
}

}  // namespace
}  // namespace instascene::generation
