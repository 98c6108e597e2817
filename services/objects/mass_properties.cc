#include "services/objects/mass_properties.h"

namespace instascene::objects {

MassProperties MeshMassProperties(const TriangleMesh& mesh, double density) {
  MassProperties out;
  if (mesh.triangles.empty()) return out;
  // Tetrahedra (ref, a, b, c) with ref = a vertex of the mesh keep the sums well conditioned.
  const Eigen::Vector3d ref = mesh.vertices[mesh.triangles[0][0]].cast<double>();
  Eigen::Matrix3d canonical;  // ∫ x x^T over the unit tetrahedron, times 6 (its volume is 1/6)
  canonical << 2, 1, 1, 1, 2, 1, 1, 1, 2;
  canonical /= 120.0;
  double volume6 = 0;                               // 6 × volume
  Eigen::Vector3d first = Eigen::Vector3d::Zero();  // ∫ x dV (relative to ref), × 6... see below
  Eigen::Matrix3d second = Eigen::Matrix3d::Zero();  // ∫ x x^T dV (relative to ref)
  for (const auto& t : mesh.triangles) {
    Eigen::Matrix3d a;
    a.col(0) = mesh.vertices[t[0]].cast<double>() - ref;
    a.col(1) = mesh.vertices[t[1]].cast<double>() - ref;
    a.col(2) = mesh.vertices[t[2]].cast<double>() - ref;
    const double det = a.determinant();
    volume6 += det;
    first += det / 24.0 * (a.col(0) + a.col(1) + a.col(2));
    second += det * a * canonical * a.transpose();
  }
  out.volume = volume6 / 6.0;
  if (out.volume == 0) return out;
  const Eigen::Vector3d com_rel = first / out.volume;
  const Eigen::Matrix3d c_com = second - out.volume * com_rel * com_rel.transpose();
  out.center = ref + com_rel;
  out.inertia = density * (c_com.trace() * Eigen::Matrix3d::Identity() - c_com);
  out.mass = density * out.volume;
  return out;
}

MassProperties Combine(const std::vector<MassProperties>& parts) {
  MassProperties out;
  for (const MassProperties& p : parts) {
    out.mass += p.mass;
    out.volume += p.volume;
    out.center += p.mass * p.center;
  }
  if (out.mass == 0) return out;
  out.center /= out.mass;
  for (const MassProperties& p : parts) {
    const Eigen::Vector3d d = p.center - out.center;
    out.inertia +=
        p.inertia + p.mass * (d.squaredNorm() * Eigen::Matrix3d::Identity() - d * d.transpose());
  }
  return out;
}

}  // namespace instascene::objects
