#include "common/geometry/camera.h"

#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace instascene {

absl::Status PinholeCamera::Validate() const {
  constexpr int kMaxSizePx = 16384;
  if (width <= 0 || height <= 0 || width > kMaxSizePx || height > kMaxSizePx) {
    return absl::InvalidArgumentError(
        absl::StrCat("camera size ", width, "x", height, " outside 1..", kMaxSizePx));
  }
  if (!(std::isfinite(fx) && std::isfinite(fy) && fx > 0.0 && fy > 0.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("camera focal length (", fx, ", ", fy, ") must be positive and finite"));
  }
  if (!(std::isfinite(cx) && std::isfinite(cy))) {
    return absl::InvalidArgumentError("camera principal point is not finite");
  }
  if (!camera_from_world.rotation.allFinite() || !camera_from_world.translation.allFinite()) {
    return absl::InvalidArgumentError("camera pose has NaN or Inf entries");
  }
  return absl::OkStatus();
}

Eigen::Vector3d PinholeCamera::PixelRayInWorld(int col, int row) const {
  const Eigen::Vector3d ray_in_camera((col + 0.5 - cx) / fx, (row + 0.5 - cy) / fy, 1.0);
  return (camera_from_world.rotation.transpose() * ray_in_camera).normalized();
}

PinholeCamera PinholeCamera::Scaled(double factor) const {
  PinholeCamera scaled = *this;
  scaled.width = static_cast<int>(std::lround(width * factor));
  scaled.height = static_cast<int>(std::lround(height * factor));
  scaled.fx *= factor;
  scaled.fy *= factor;
  scaled.cx *= factor;
  scaled.cy *= factor;
  return scaled;
}

PinholeCamera OrbitCamera(const Eigen::Vector3d& center_in_world,
                          const Eigen::Vector3d& up_in_world, double distance, double azimuth_deg,
                          double elevation_deg, int width, int height, double fov_x_deg) {
  const Eigen::Vector3d up = up_in_world.normalized();
  // Any unit vector orthogonal to up defines azimuth 0.
  Eigen::Vector3d ref =
      std::abs(up.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d axis0 = (ref - ref.dot(up) * up).normalized();
  const Eigen::Vector3d axis1 = up.cross(axis0);
  constexpr double kDeg = std::numbers::pi / 180.0;
  const double az = azimuth_deg * kDeg;
  const double el = elevation_deg * kDeg;
  const Eigen::Vector3d dir =
      std::cos(el) * (std::cos(az) * axis0 + std::sin(az) * axis1) + std::sin(el) * up;
  PinholeCamera camera;
  camera.width = width;
  camera.height = height;
  camera.fx = camera.fy = 0.5 * width / std::tan(0.5 * fov_x_deg * kDeg);
  camera.cx = 0.5 * width;
  camera.cy = 0.5 * height;
  camera.camera_from_world = LookAt(center_in_world + distance * dir, center_in_world, up);
  return camera;
}

}  // namespace instascene
