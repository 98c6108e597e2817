#include <gtest/gtest.h>

#include <random>

#include "common/geometry/camera.h"
#include "common/geometry/point_index.h"
#include "common/geometry/rigid.h"

namespace instascene {
namespace {

TEST(Rigid3d, InverseComposesToIdentity) {
  std::mt19937 rng(3);
  std::normal_distribution<double> n;
  for (int trial = 0; trial < 20; ++trial) {
    Rigid3d a{RotationFromQuaternionWxyz(n(rng), n(rng), n(rng), n(rng)),
              Eigen::Vector3d(n(rng), n(rng), n(rng))};
    Rigid3d id = a * a.Inverse();
    EXPECT_LT((id.rotation - Eigen::Matrix3d::Identity()).norm(), 1e-12);
    EXPECT_LT(id.translation.norm(), 1e-12);
    Eigen::Vector4d q = QuaternionWxyzFromRotation(a.rotation);
    EXPECT_LT((RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]) - a.rotation).norm(), 1e-12);
  }
}

TEST(Rigid3d, FromMatrixRejectsNonRotations) {
  Eigen::Matrix<double, 3, 4> m = Eigen::Matrix<double, 3, 4>::Zero();
  m.leftCols<3>() = 2.0 * Eigen::Matrix3d::Identity();
  EXPECT_FALSE(RigidFromMatrix(m).ok());
  m.leftCols<3>() = -Eigen::Matrix3d::Identity();  // det -1
  EXPECT_FALSE(RigidFromMatrix(m).ok());
  m.leftCols<3>() = Eigen::Matrix3d::Identity();
  m(0, 3) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(RigidFromMatrix(m).ok());
  m(0, 3) = 1.0;
  EXPECT_TRUE(RigidFromMatrix(m).ok());
}

TEST(LookAt, TargetProjectsToPrincipalPointAndUpIsUp) {
  PinholeCamera cam = OrbitCamera({1, 2, 3}, {0, 0, 1}, 5.0, 30.0, 20.0, 64, 48, 60.0);
  ASSERT_TRUE(cam.Validate().ok());
  Eigen::Vector3d c = cam.camera_from_world * Eigen::Vector3d(1, 2, 3);
  EXPECT_NEAR(c.z(), 5.0, 1e-9);
  Eigen::Vector2d px = cam.ProjectFromCamera(c);
  EXPECT_NEAR(px.x(), 32.0, 1e-9);
  EXPECT_NEAR(px.y(), 24.0, 1e-9);
  // A point above the target appears above the centre (smaller row).
  Eigen::Vector2d above = cam.ProjectFromCamera(cam.camera_from_world * Eigen::Vector3d(1, 2, 3.5));
  EXPECT_LT(above.y(), 24.0);
  EXPECT_NEAR((cam.CenterInWorld() - Eigen::Vector3d(1, 2, 3)).norm(), 5.0, 1e-9);
}

TEST(PinholeCamera, PixelRayHitsPixelCentre) {
  PinholeCamera cam = OrbitCamera({0, 0, 0}, {0, -1, 0}, 3.0, 10.0, 40.0, 40, 30, 50.0);
  Eigen::Vector3d ray = cam.PixelRayInWorld(7, 11);
  Eigen::Vector3d p = cam.CenterInWorld() + 2.5 * ray;
  Eigen::Vector2d px = cam.ProjectFromCamera(cam.camera_from_world * p);
  EXPECT_NEAR(px.x(), 7.5, 1e-9);
  EXPECT_NEAR(px.y(), 11.5, 1e-9);
}

TEST(PinholeCamera, ValidateRejectsBadIntrinsics) {
  PinholeCamera cam;
  EXPECT_FALSE(cam.Validate().ok());
  cam.width = 10;
  cam.height = 10;
  cam.fx = cam.fy = 5;
  EXPECT_TRUE(cam.Validate().ok());
  cam.fx = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(cam.Validate().ok());
}

}  // namespace
}  // namespace instascene

namespace instascene {
namespace {

TEST(PointIndex3, MatchesBruteForceOnRandomPoints) {
  std::mt19937 rng(12);
  std::uniform_real_distribution<float> u(-1, 1);
  std::vector<Eigen::Vector3f> pts(2000);
  for (auto& p : pts) p = {u(rng), u(rng), u(rng)};
  PointIndex3 index(pts);
  for (int q = 0; q < 200; ++q) {
    const Eigen::Vector3f query(u(rng), u(rng), u(rng));
    uint32_t best = 0;
    float best_d = 1e30f;
    std::vector<uint32_t> within;
    for (uint32_t i = 0; i < pts.size(); ++i) {
      const float d = (pts[i] - query).squaredNorm();
      if (d < best_d) {
        best_d = d;
        best = i;
      }
      if (d <= 0.2f * 0.2f) within.push_back(i);
    }
    const auto [index_best, index_d] = index.Nearest(query);
    EXPECT_EQ(index_best, best);
    EXPECT_FLOAT_EQ(index_d, best_d);
    EXPECT_EQ(index.WithinRadius(query, 0.2f), within);
  }
}

}  // namespace
}  // namespace instascene
