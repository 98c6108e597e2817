#include "services/generation/normal_consistency.h"

#include <Eigen/Geometry>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene::generation {

namespace {

absl::Status CheckSize(const char* name, size_t size, size_t expected) {
  if (size == expected) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat("normal consistency: ", name, " has ", size,
                                                 " values, the camera's image needs ", expected));
}

absl::Status CheckBuffers(const std::vector<float>& normal, const std::vector<float>& depth,
                          const std::vector<float>& alpha, const std::vector<uint8_t>& mask,
                          const PinholeCamera& camera, const std::vector<float>* d_normal,
                          const std::vector<float>* d_depth) {
  const int w = camera.width, h = camera.height;
  if (w <= 0 || h <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("normal consistency: camera of ", w, "x", h, " pixels"));
  }
  if (d_normal == nullptr || d_depth == nullptr) {
    return absl::InvalidArgumentError("normal consistency: null gradient buffer");
  }
  const size_t pixels = static_cast<size_t>(w) * h;
  for (absl::Status s :
       {CheckSize("normal", normal.size(), 3 * pixels), CheckSize("depth", depth.size(), pixels),
        CheckSize("alpha", alpha.size(), pixels),
        mask.empty() ? absl::OkStatus() : CheckSize("mask", mask.size(), pixels),
        CheckSize("d_normal", d_normal->size(), 3 * pixels),
        CheckSize("d_depth", d_depth->size(), pixels)}) {
    if (!s.ok()) return s;
  }
  return absl::OkStatus();
}

// The depth image's points: P = depth * ray, the ray of pixel (x, y) with camera z = 1.
struct DepthPoints {
  const PinholeCamera& camera;
  const std::vector<float>& depth;
  Eigen::Vector3d Ray(int x, int y) const {
    return Eigen::Vector3d((x + 0.5 - camera.cx) / camera.fx, (y + 0.5 - camera.cy) / camera.fy,
                           1.0);
  }
  Eigen::Vector3d Point(int x, int y) const {
    return double(depth[size_t(y) * camera.width + x]) * Ray(x, y);
  }
};

// Interior pixel (x, y) with depth at its 4 neighbours: the rendered normal (camera frame)
// dotted with alpha times the unit normal of the depth's central differences; the gradients of
// -scale times it added to d_normal (world frame) and d_depth. 0 where the surface normal is
// undefined.
double PixelConsistency(const DepthPoints& points, const std::vector<float>& normal,
                        const std::vector<float>& alpha, int x, int y, double scale,
                        std::vector<float>* d_normal, std::vector<float>* d_depth) {
  const int w = points.camera.width;
  const size_t i = size_t(y) * w + x;
  const Eigen::Vector3d a = points.Point(x, y + 1) - points.Point(x, y - 1);
  const Eigen::Vector3d b = points.Point(x + 1, y) - points.Point(x - 1, y);
  const Eigen::Vector3d c = a.cross(b);
  const double length = c.norm();
  if (!(length > 0)) return 0;
  const Eigen::Matrix3d cam_from_world = points.camera.camera_from_world.rotation;
  const Eigen::Vector3d unit = c / length;
  const Eigen::Vector3d surf = double(alpha[i]) * unit;
  const Eigen::Vector3d rend =
      cam_from_world * Eigen::Vector3d(normal[3 * i], normal[3 * i + 1], normal[3 * i + 2]);
  // dL/dn_rend (camera) = -surf; to the world frame with the transpose.
  const Eigen::Vector3d d_rend_world = cam_from_world.transpose() * (-scale * surf);
  for (int k = 0; k < 3; ++k) (*d_normal)[3 * i + k] += static_cast<float>(d_rend_world[k]);
  // dL/dunit = -alpha rend; through the normalisation and the cross product (c = a x b).
  const Eigen::Vector3d d_unit = -scale * double(alpha[i]) * rend;
  const Eigen::Vector3d d_c = (d_unit - unit * unit.dot(d_unit)) / length;
  const Eigen::Vector3d d_a = b.cross(d_c), d_b = d_c.cross(a);
  auto add_depth = [&](int px, int py, const Eigen::Vector3d& d_point) {
    (*d_depth)[size_t(py) * w + px] += static_cast<float>(points.Ray(px, py).dot(d_point));
  };
  add_depth(x, y + 1, d_a);
  add_depth(x, y - 1, -d_a);
  add_depth(x + 1, y, d_b);
  add_depth(x - 1, y, -d_b);
  return rend.dot(surf);
}

}  // namespace

absl::StatusOr<double> NormalConsistency(
    const std::vector<float>& normal, const std::vector<float>& depth,
    const std::vector<float>& alpha, const std::vector<uint8_t>& mask, const PinholeCamera& camera,
    double weight, std::vector<float>* d_normal, std::vector<float>* d_depth) {
  RETURN_IF_ERROR(CheckBuffers(normal, depth, alpha, mask, camera, d_normal, d_depth));
  const int w = camera.width, h = camera.height;
  const size_t pixels = static_cast<size_t>(w) * h;
  size_t counted = 0;
  for (size_t i = 0; i < pixels; ++i) counted += mask.empty() || mask[i] != 0;
  if (counted == 0) return 0.0;
  const DepthPoints points{camera, depth};
  const double scale = weight / counted;
  double sum = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t i = size_t(y) * w + x;
      if (!mask.empty() && mask[i] == 0) continue;
      sum += 1.0;
      if (x == 0 || y == 0 || x == w - 1 || y == h - 1) continue;
      if (!(depth[i - 1] > 0 && depth[i + 1] > 0 && depth[i - w] > 0 && depth[i + w] > 0)) continue;
      sum -= PixelConsistency(points, normal, alpha, x, y, scale, d_normal, d_depth);
    }
  }
  return sum / counted;
}

}  // namespace instascene::generation
