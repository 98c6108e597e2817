// services/objects/mass_properties.h: volume, centre of mass and inertia tensor of a closed,
// outward-oriented triangle mesh of uniform density (divergence theorem over the signed tetrahedra
// the triangles span with a reference point; exact for any closed polyhedron), and their sum over
// several bodies. Used for URDF/MJCF inertials of collision geometry. Double precision.
#pragma once

#include <vector>

#include <Eigen/Dense>

#include "common/geometry/triangle_mesh.h"

namespace instascene::objects {

struct MassProperties {
  double mass = 0;                                    // density × volume
  double volume = 0;                                  // signed: negative if inward-oriented
  Eigen::Vector3d center = Eigen::Vector3d::Zero();   // centre of mass
  Eigen::Matrix3d inertia = Eigen::Matrix3d::Zero();  // about the centre of mass, mesh axes
};

MassProperties MeshMassProperties(const TriangleMesh& mesh, double density = 1.0);
// Several bodies as one rigid body (parallel-axis theorem).
MassProperties Combine(const std::vector<MassProperties>& parts);

}  // namespace instascene::objects
