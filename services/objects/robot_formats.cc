#include "services/objects/robot_formats.h"

#include <cstring>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace instascene::objects {
namespace {

void Put(std::string* out, const void* data, size_t n) {
  out->append(static_cast<const char*>(data), n);
}

std::string V(const Eigen::Vector3d& v) {
  return absl::StrFormat("%.9g %.9g %.9g", v.x(), v.y(), v.z());
}

}  // namespace

std::string EncodeBinaryStl(const TriangleMesh& mesh, const std::string& name) {
  std::string out(80, '\0');
  std::memcpy(out.data(), name.data(), std::min<size_t>(name.size(), 79));
  const uint32_t n = static_cast<uint32_t>(mesh.triangles.size());
  Put(&out, &n, 4);
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3f& a = mesh.vertices[t[0]];
    const Eigen::Vector3f& b = mesh.vertices[t[1]];
    const Eigen::Vector3f& c = mesh.vertices[t[2]];
    Eigen::Vector3f normal = (b - a).cross(c - a);
    if (normal.norm() > 0) normal.normalize();
    Put(&out, normal.data(), 12);
    Put(&out, a.data(), 12);
    Put(&out, b.data(), 12);
    Put(&out, c.data(), 12);
    const uint16_t attribute = 0;
    Put(&out, &attribute, 2);
  }
  return out;
}

std::string UrdfXml(const RigidObjectModel& m) {
  const Eigen::Matrix3d& I = m.mass.inertia;
  std::string xml = absl::StrCat(
      "<?xml version=\"1.0\"?>\n<robot name=\"", m.name, "\">\n  <link name=\"", m.name,
      "\">\n    <inertial>\n      <origin xyz=\"", V(m.mass.center),
      "\" rpy=\"0 0 0\"/>\n      <mass value=\"", absl::StrFormat("%.9g", m.mass.mass),
      "\"/>\n      <inertia ",
      absl::StrFormat(
          "ixx=\"%.9g\" ixy=\"%.9g\" ixz=\"%.9g\" iyy=\"%.9g\" iyz=\"%.9g\" izz=\"%.9g\"", I(0, 0),
          I(0, 1), I(0, 2), I(1, 1), I(1, 2), I(2, 2)),
      "/>\n    </inertial>\n    <visual>\n      <geometry>\n        <mesh filename=\"",
      m.visual_mesh, "\"/>\n      </geometry>\n      <material name=\"", m.name,
      "_colour\">\n        <color rgba=\"",
      absl::StrFormat("%.4f %.4f %.4f 1", m.color.x(), m.color.y(), m.color.z()),
      "\"/>\n      </material>\n    </visual>\n");
  for (const std::string& part : m.collision_meshes)
    absl::StrAppend(&xml, "    <collision>\n      <geometry>\n        <mesh filename=\"", part,
                    "\"/>\n      </geometry>\n    </collision>\n");
  absl::StrAppend(&xml, "  </link>\n</robot>\n");
  return xml;
}

std::string MjcfXml(const RigidObjectModel& m) {
  const Eigen::Matrix3d& I = m.mass.inertia;
  std::string xml = absl::StrCat("<mujoco model=\"", m.name, "\">\n  <asset>\n    <mesh name=\"",
                                 m.name, "_visual\" file=\"", m.visual_mesh, "\"/>\n");
  for (size_t p = 0; p < m.collision_meshes.size(); ++p)
    absl::StrAppend(&xml, "    <mesh name=\"", m.name, "_part", p, "\" file=\"",
                    m.collision_meshes[p], "\"/>\n");
  absl::StrAppend(&xml, "  </asset>\n  <worldbody>\n    <body name=\"", m.name,
                  "\">\n      <freejoint/>\n", "      <inertial pos=\"", V(m.mass.center),
                  "\" mass=\"", absl::StrFormat("%.9g", m.mass.mass), "\" fullinertia=\"",
                  absl::StrFormat("%.9g %.9g %.9g %.9g %.9g %.9g", I(0, 0), I(1, 1), I(2, 2),
                                  I(0, 1), I(0, 2), I(1, 2)),
                  "\"/>\n      <geom type=\"mesh\" mesh=\"", m.name,
                  "_visual\" contype=\"0\" conaffinity=\"0\" group=\"1\" rgba=\"",
                  absl::StrFormat("%.4f %.4f %.4f 1", m.color.x(), m.color.y(), m.color.z()),
                  "\"/>\n");
  for (size_t p = 0; p < m.collision_meshes.size(); ++p)
    absl::StrAppend(&xml, "      <geom type=\"mesh\" mesh=\"", m.name, "_part", p,
                    "\" group=\"3\"/>\n");
  absl::StrAppend(&xml, "    </body>\n  </worldbody>\n</mujoco>\n");
  return xml;
}

}  // namespace instascene::objects
