#include "services/generation/diffusion/unseen_region.h"

#include <gtest/gtest.h>

#include "common/mesh/ray_caster.h"
#include "common/synth/primitives.h"

namespace instascene::generation::diffusion {
namespace {

// A sphere (radius 0.3, centre (0, 0, 0.3)) seen by real cameras on its +x side only: its inside
// and the space behind it are unseen, and the instance is its observed +x half. A target on the
// -x side looks through that unseen space onto the inside of the observed half; a target on the
// +x side looks through space the real views saw empty onto the observed surface.
class UnseenRegionTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ShapeSpec spec;
    spec.kind = ShapeKind::kSphere;
    spec.size = {0.3f, 0, 0};
    const TriangleMesh sphere = MakeShapeMesh(spec, 64);
    auto caster = RayCaster::Create(sphere);
    ASSERT_TRUE(caster.ok());
    mesh_ = std::move(*caster);
    // The instance as the pipeline has it: the observed surface only, the +x half.
    TriangleMesh half = sphere;
    half.triangles.clear();
    for (const auto& t : sphere.triangles) {
      if (sphere.vertices[t[0]].x() + sphere.vertices[t[1]].x() + sphere.vertices[t[2]].x() > 0)
        half.triangles.push_back(t);
    }
    auto observed = RayCaster::Create(half);
    ASSERT_TRUE(observed.ok());
    observed_ = std::move(*observed);
    for (int az = -60; az <= 60; az += 10) {
      for (int el : {-20, 10, 40})
        cameras_.push_back(OrbitCamera(centre_, {0, 0, 1}, 1.5, az, el, 96, 96, 50));
    }
    frame_.center = centre_.cast<float>();
    frame_.radius = 0.3f;
    auto grid = FreeSpaceGrid::Carve(cameras_, *mesh_, frame_, FreeSpaceOptions{});
    ASSERT_TRUE(grid.ok()) << grid.status();
    grid_ = std::make_unique<FreeSpaceGrid>(std::move(*grid));
  }

  // The share of the target's pixels whose ray meets the cube centre +- R that are unseen.
  double UnseenShare(double azimuth, const UnseenOptions& options = {}) {
    const PinholeCamera target = OrbitCamera(centre_, {0, 0, 1}, 1.2, azimuth, 15, 32, 32, 40);
    std::vector<float> depth(32 * 32, 0.0f);
    const Eigen::Vector3f eye = target.CenterInWorld().cast<float>();
    const Eigen::Vector3f axis = target.camera_from_world.rotation.row(2).transpose().cast<float>();
    for (int y = 0; y < 32; ++y) {
      for (int x = 0; x < 32; ++x) {
        const Eigen::Vector3f dir = target.PixelRayInWorld(x, y).cast<float>();
        const RayHit hit = observed_->Cast(eye, dir);
        if (hit.hit) depth[y * 32 + x] = hit.distance * dir.dot(axis);
      }
    }
    const std::vector<uint8_t> unseen = UnseenRegion(*grid_, frame_, target, depth, 256, options);
    int count = 0;
    for (uint8_t u : unseen) count += u;
    return count / 1024.0;
  }

  Eigen::Vector3d centre_{0, 0, 0.3};
  std::unique_ptr<RayCaster> mesh_, observed_;
  std::vector<PinholeCamera> cameras_;
  ObjectFrame frame_;
  std::unique_ptr<FreeSpaceGrid> grid_;
};

TEST_F(UnseenRegionTest, TheShadowBehindTheObjectIsUnseenAndTheObservedSideIsNot) {
  const double behind = UnseenShare(180), front = UnseenShare(0);
  std::printf("unseen share: %.3f from behind, %.3f from the observed side\n", behind, front);
  EXPECT_GT(behind, 0.25);
  EXPECT_LT(front, 0.02);
}

TEST_F(UnseenRegionTest, TheCleaningErodesSpecklesAndDilatesRegions) {
  UnseenOptions raw;
  raw.erode_px = raw.dilate_px = 0;
  UnseenOptions dilate_only = raw;
  dilate_only.dilate_px = 24;  // 3 cells at 32 / 256
  EXPECT_GT(UnseenShare(180, dilate_only), UnseenShare(180, raw));
  UnseenOptions erode_only = raw;
  erode_only.erode_px = 24;
  EXPECT_LT(UnseenShare(180, erode_only), UnseenShare(180, raw));
}

TEST_F(UnseenRegionTest, NothingUnderTheSupportPlaneCounts) {
  // With the support plane at the sphere's top, every sample lies under it.
  frame_.has_support = true;
  frame_.support_height = 0.61f;
  EXPECT_EQ(UnseenShare(180), 0.0);
}

}  // namespace
}  // namespace instascene::generation::diffusion
