#include "common/mesh/surfel_mesh.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "common/geometry/rigid.h"

namespace instascene {

TriangleMesh SurfelDiscs(const GaussianCloud& surfels, const std::vector<uint32_t>& indices,
                         const SurfelDiscOptions& options, std::vector<uint32_t>* source) {
  TriangleMesh mesh;
  if (source != nullptr) source->clear();
  const int segments = std::max(3, options.segments);
  const size_t count = indices.empty() ? surfels.size() : indices.size();
  const float min_logit =
      std::log(options.min_opacity) - std::log1p(-std::min(options.min_opacity, 0.999999f));
  for (size_t k = 0; k < count; ++k) {
    const uint32_t g = indices.empty() ? static_cast<uint32_t>(k) : indices[k];
    if (g >= surfels.size() || surfels.opacity_logits[g] < min_logit) continue;
    const float* q = &surfels.rotations[4 * g];
    const Eigen::Matrix3f r = RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]).cast<float>();
    const float* ls = &surfels.log_scales[surfels.num_scales * g];
    const Eigen::Vector3f u = r.col(0) * (options.extent_sigma * std::exp(ls[0]));
    const Eigen::Vector3f v = r.col(1) * (options.extent_sigma * std::exp(ls[1]));
    const Eigen::Vector3f center(&surfels.positions[3 * g]);
    const uint32_t base = static_cast<uint32_t>(mesh.vertices.size());
    mesh.vertices.push_back(center);
    for (int s = 0; s < segments; ++s) {
      const float angle = 2.0f * std::numbers::pi_v<float> * static_cast<float>(s) / segments;
      mesh.vertices.push_back(center + std::cos(angle) * u + std::sin(angle) * v);
    }
    for (int s = 0; s < segments; ++s) {
      mesh.triangles.push_back({base, base + 1 + static_cast<uint32_t>(s),
                                base + 1 + static_cast<uint32_t>((s + 1) % segments)});
      if (source != nullptr) source->push_back(g);
    }
  }
  return mesh;
}

}  // namespace instascene
