// common/geometry/camera.h: the pinhole camera every module renders and projects with.
//
// Intrinsics follow COLMAP: the image's top-left corner is (0, 0) and the centre of pixel (i, j) is
// at (i + 0.5, j + 0.5), so a centred principal point is (width / 2, height / 2). Extrinsics are
// camera_from_world with OpenCV axes (x right, y down, z forward). Value type, thread-safe.
#pragma once

#include <string>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "common/geometry/rigid.h"

namespace instascene {

struct PinholeCamera {
  int width = 0;    // image width, px
  int height = 0;   // image height, px
  double fx = 0.0;  // focal length along x, px
  double fy = 0.0;  // focal length along y, px
  double cx = 0.0;  // principal point x, px (COLMAP convention, see above)
  double cy = 0.0;  // principal point y, px
  Rigid3d camera_from_world;

  // OK when sizes are positive and bounded (<= 16384 px), focal lengths positive and finite, and
  // the principal point finite.
  absl::Status Validate() const;

  Eigen::Vector3d CenterInWorld() const { return camera_from_world.Inverse().translation; }

  // Pixel coordinates (COLMAP convention) of a point in camera coordinates; z must be positive.
  Eigen::Vector2d ProjectFromCamera(const Eigen::Vector3d& x_in_camera) const {
    return {fx * x_in_camera.x() / x_in_camera.z() + cx,
            fy * x_in_camera.y() / x_in_camera.z() + cy};
  }
  // True when a world point lies in front of the camera and projects inside the image; its
  // camera coordinates go to *x_in_camera when given.
  bool SeesPoint(const Eigen::Vector3d& x_in_world, Eigen::Vector3d* x_in_camera = nullptr) const {
    const Eigen::Vector3d x = camera_from_world * x_in_world;
    if (x_in_camera != nullptr) *x_in_camera = x;
    if (x.z() <= 0) return false;
    const Eigen::Vector2d px = ProjectFromCamera(x);
    return px.x() >= 0 && px.y() >= 0 && px.x() < width && px.y() < height;
  }
  // Unit ray direction in world coordinates through the centre of pixel (col, row).
  Eigen::Vector3d PixelRayInWorld(int col, int row) const;

  // The same camera with the image scaled by `factor` (intrinsics and size scaled).
  PinholeCamera Scaled(double factor) const;
};

// A camera on a sphere around `center_in_world` at `distance`, at azimuth/elevation (degrees)
// measured in the plane orthogonal to `up_in_world`, looking at the centre; fov_x_deg sets fx from
// the width.
PinholeCamera OrbitCamera(const Eigen::Vector3d& center_in_world,
                          const Eigen::Vector3d& up_in_world, double distance, double azimuth_deg,
                          double elevation_deg, int width, int height, double fov_x_deg);

}  // namespace instascene
