// services/objects/robot_formats.h: the files robot stacks consume for one rigid object: binary
// STL meshes, a URDF (ROS; checked with urdfdom's check_urdf) and an MJCF model (MuJoCo; loaded and
// simulated by the tests), both referencing the visual mesh and the convex collision parts by
// relative path, with mass and inertia from the collision geometry.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Dense>

#include "common/geometry/triangle_mesh.h"
#include "services/objects/mass_properties.h"

namespace instascene::objects {

std::string EncodeBinaryStl(const TriangleMesh& mesh, const std::string& name);

struct RigidObjectModel {
  std::string name;                                         // XML-safe: [A-Za-z0-9_]
  std::string visual_mesh;                                  // relative path (STL)
  std::vector<std::string> collision_meshes;                // relative paths (STL, convex)
  Eigen::Vector3f color = Eigen::Vector3f::Constant(0.7f);  // mean linear RGB
  MassProperties mass;                                      // kg, metres, object frame
};

std::string UrdfXml(const RigidObjectModel& model);
// A standalone MuJoCo model: the object as a free body at the origin (include it in a scene with
// <include file=...> or load it alone).
std::string MjcfXml(const RigidObjectModel& model);

}  // namespace instascene::objects
