// common/geometry/rigid.h: rigid transforms named target_from_source (COLMAP convention).
//
// A Rigid3d maps points: x_in_target = rotation * x_in_source + translation. Value type,
// thread-safe.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "absl/status/statusor.h"

namespace instascene {

struct Rigid3d {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Eigen::Vector3d operator*(const Eigen::Vector3d& x_in_source) const {
    return rotation * x_in_source + translation;
  }
  // (a_from_b * b_from_c) = a_from_c.
  Rigid3d operator*(const Rigid3d& other) const {
    return {rotation * other.rotation, rotation * other.translation + translation};
  }
  Rigid3d Inverse() const {
    Eigen::Matrix3d rt = rotation.transpose();
    return {rt, -(rt * translation)};
  }
  Eigen::Matrix<double, 3, 4> ToMatrix() const {
    Eigen::Matrix<double, 3, 4> m;
    m << rotation, translation;
    return m;
  }
};

// Builds a Rigid3d from a 3x4 [R|t]; fails unless R is a rotation (orthonormal, det +1, tol 1e-4)
// and every entry is finite.
absl::StatusOr<Rigid3d> RigidFromMatrix(const Eigen::Matrix<double, 3, 4>& matrix);

// Rotation matrix of a unit quaternion given w-first; the input is normalised first.
Eigen::Matrix3d RotationFromQuaternionWxyz(double w, double x, double y, double z);

// Quaternion (w, x, y, z) with w >= 0 of a rotation matrix.
Eigen::Vector4d QuaternionWxyzFromRotation(const Eigen::Matrix3d& rotation);

// camera_from_world of a camera at `eye_in_world` looking at `target_in_world`, with OpenCV axes
// (x right, y down, z forward); `up_in_world` is the direction that appears upwards in the image.
// `up_in_world` must not be parallel to the viewing direction.
Rigid3d LookAt(const Eigen::Vector3d& eye_in_world, const Eigen::Vector3d& target_in_world,
               const Eigen::Vector3d& up_in_world);

}  // namespace instascene
