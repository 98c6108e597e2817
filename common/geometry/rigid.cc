#include "common/geometry/rigid.h"

#include <cmath>

#include <Eigen/SVD>

#include "absl/status/status.h"

namespace instascene {

absl::StatusOr<Rigid3d> RigidFromMatrix(const Eigen::Matrix<double, 3, 4>& matrix) {
  if (!matrix.allFinite()) return absl::InvalidArgumentError("pose has NaN or Inf entries");
  Rigid3d rigid{matrix.leftCols<3>(), matrix.col(3)};
  const double orthogonality =
      (rigid.rotation * rigid.rotation.transpose() - Eigen::Matrix3d::Identity())
          .cwiseAbs()
          .maxCoeff();
  if (orthogonality > 1e-4 || rigid.rotation.determinant() < 0.0) {
    return absl::InvalidArgumentError(
        "pose rotation is not a proper rotation (orthonormal with determinant +1)");
  }
  // Remove the small non-orthogonality that text formats leave (nearest rotation, by SVD).
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(rigid.rotation, Eigen::ComputeFullU | Eigen::ComputeFullV);
  rigid.rotation = svd.matrixU() * svd.matrixV().transpose();
  return rigid;
}

Eigen::Matrix3d RotationFromQuaternionWxyz(double w, double x, double y, double z) {
  return Eigen::Quaterniond(w, x, y, z).normalized().toRotationMatrix();
}

Eigen::Vector4d QuaternionWxyzFromRotation(const Eigen::Matrix3d& rotation) {
  Eigen::Quaterniond q(rotation);
  q.normalize();
  Eigen::Vector4d wxyz(q.w(), q.x(), q.y(), q.z());
  if (wxyz[0] < 0.0) wxyz = -wxyz;
  return wxyz;
}

Rigid3d LookAt(const Eigen::Vector3d& eye_in_world, const Eigen::Vector3d& target_in_world,
               const Eigen::Vector3d& up_in_world) {
  const Eigen::Vector3d forward = (target_in_world - eye_in_world).normalized();
  const Eigen::Vector3d right = forward.cross(up_in_world).normalized();
  const Eigen::Vector3d down = forward.cross(right);
  Eigen::Matrix3d world_from_camera_rotation;
  world_from_camera_rotation << right, down, forward;
  Rigid3d world_from_camera{world_from_camera_rotation, eye_in_world};
  return world_from_camera.Inverse();
}

}  // namespace instascene
