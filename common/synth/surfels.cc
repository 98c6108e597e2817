#include "common/synth/surfels.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "common/geometry/rigid.h"
#include "common/splat/sh.h"

namespace instascene {
namespace {

// Smooth 2D value noise in [0, 1].
float ValueNoise(float x, float y, uint32_t seed) {
  auto hash = [seed](int ix, int iy) {
    uint32_t h = static_cast<uint32_t>(ix) * 374761393u + static_cast<uint32_t>(iy) * 668265263u +
                 seed * 2246822519u;
    h = (h ^ (h >> 13)) * 1274126177u;
    return static_cast<float>((h ^ (h >> 16)) & 0xffffff) / 16777215.0f;
  };
  const int ix = static_cast<int>(std::floor(x)), iy = static_cast<int>(std::floor(y));
  const float fx = x - ix, fy = y - iy;
  const float sx = fx * fx * (3 - 2 * fx), sy = fy * fy * (3 - 2 * fy);
  const float a = hash(ix, iy), b = hash(ix + 1, iy), c = hash(ix, iy + 1),
              d = hash(ix + 1, iy + 1);
  return (a + (b - a) * sx) + ((c + (d - c) * sx) - (a + (b - a) * sx)) * sy;
}

}  // namespace

Eigen::Vector3f ShadeUv(const Appearance& ap, const Eigen::Vector2f& uv) {
  const float u = uv.x() * ap.frequency, v = uv.y() * ap.frequency;
  float t = 0.0f;
  switch (ap.pattern) {
    case TexturePattern::kSolid:
      t = 0.0f;
      break;
    case TexturePattern::kStripes:
      t = std::fmod(std::floor(v), 2.0f) == 0.0f ? 0.0f : 1.0f;
      break;
    case TexturePattern::kChecker:
      t = (static_cast<int>(std::floor(u)) + static_cast<int>(std::floor(v))) % 2 == 0 ? 0.0f
                                                                                       : 1.0f;
      break;
    case TexturePattern::kDots: {
      const float du = u - std::floor(u) - 0.5f, dv = v - std::floor(v) - 0.5f;
      t = du * du + dv * dv < 0.09f ? 1.0f : 0.0f;
      break;
    }
    case TexturePattern::kNoise:
      t = ValueNoise(u, v, ap.noise_seed) * 0.6f +
          ValueNoise(3 * u, 3 * v, ap.noise_seed + 1) * 0.4f;
      break;
  }
  return (1.0f - t) * ap.color_a + t * ap.color_b;
}

namespace {

// What every surfel of one AppendSurfels call shares.
struct SurfelStyle {
  const Appearance* appearance;
  Eigen::Vector3f light;
  float log_sigma, opacity_logit;
};

// Surfel i at p, tangent tu, unit normal n; its colour from the texture at uv, lit.
void PutSurfel(const SurfelStyle& style, size_t i, const Eigen::Vector3f& p,
               const Eigen::Vector3f& tu, const Eigen::Vector3f& n, const Eigen::Vector2f& uv,
               GaussianCloud* cloud) {
  const int stride = cloud->sh_stride();
  const Eigen::Vector3f tv = n.cross(tu);
  Eigen::Matrix3d frame;
  frame << tu.cast<double>(), tv.cast<double>(), n.cast<double>();
  const Eigen::Vector4d q = QuaternionWxyzFromRotation(frame);
  const float shade = 0.45f + 0.55f * std::abs(n.dot(style.light));
  const Eigen::Vector3f rgb = (ShadeUv(*style.appearance, uv) * shade).cwiseMin(1.0f);
  for (int a = 0; a < 3; ++a) cloud->positions[3 * i + a] = p[a];
  cloud->log_scales[2 * i] = cloud->log_scales[2 * i + 1] = style.log_sigma;
  for (int a = 0; a < 4; ++a) cloud->rotations[4 * i + a] = static_cast<float>(q[a]);
  cloud->opacity_logits[i] = style.opacity_logit;
  for (int c = 0; c < 3; ++c) cloud->sh[static_cast<size_t>(stride) * i + c] = RgbToSh0(rgb[c]);
}

// Grows every array of `cloud` by `added` (extras keep their values; new entries get
// extra_value).
void GrowCloud(size_t added, float extra_value, GaussianCloud* cloud) {
  const size_t base = cloud->size();
  cloud->positions.resize(3 * (base + added));
  cloud->log_scales.resize(2 * (base + added));
  cloud->rotations.resize(4 * (base + added));
  cloud->opacity_logits.resize(base + added);
  cloud->sh.resize(static_cast<size_t>(cloud->sh_stride()) * (base + added), 0.0f);
  for (ExtraChannel& e : cloud->extras) e.values.resize(base + added, extra_value);
}

// A point on triangle t (barycentric draws r1, r2 folded into the triangle): its position, the
// triangle's first edge direction and normal, its uv.
void PointOnTriangle(const TriangleMesh& mesh, size_t t, double r1, double r2, Eigen::Vector3f* p,
                     Eigen::Vector3f* tangent, Eigen::Vector3f* n, Eigen::Vector2f* uv) {
  const auto& tri = mesh.triangles[t];
  if (r1 + r2 > 1.0) {
    r1 = 1.0 - r1;
    r2 = 1.0 - r2;
  }
  const float b1 = static_cast<float>(r1), b2 = static_cast<float>(r2), b0 = 1.0f - b1 - b2;
  *p = b0 * mesh.vertices[tri[0]] + b1 * mesh.vertices[tri[1]] + b2 * mesh.vertices[tri[2]];
  const Eigen::Vector3f e1 = mesh.vertices[tri[1]] - mesh.vertices[tri[0]];
  *n = e1.cross(mesh.vertices[tri[2]] - mesh.vertices[tri[0]]).normalized();
  *tangent = e1.normalized();
  *uv = Eigen::Vector2f::Zero();
  if (mesh.uvs.size() == mesh.vertices.size())
    *uv = b0 * mesh.uvs[tri[0]] + b1 * mesh.uvs[tri[1]] + b2 * mesh.uvs[tri[2]];
}

}  // namespace

void AppendSurfels(const TriangleMesh& mesh, size_t count, const Appearance& appearance,
                   const SurfelSampling& sampling, std::mt19937_64& rng, GaussianCloud* cloud,
                   float extra_value, const std::vector<SurfelApex>& apices) {
  const size_t num_tris = mesh.triangles.size();
  if (num_tris == 0 || count == 0) return;
  std::vector<double> cdf(num_tris);
  double total = 0.0;
  for (size_t t = 0; t < num_tris; ++t) cdf[t] = (total += mesh.TriangleArea(t));
  if (total <= 0.0) return;
  const float sigma = sampling.scale_factor * static_cast<float>(std::sqrt(total / count));
  const SurfelStyle style{&appearance, sampling.light_dir.normalized(), std::log(sigma),
                          std::log(sampling.opacity / (1.0f - sampling.opacity))};
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  const size_t base = cloud->size();
  const int stride = cloud->sh_stride();
  GrowCloud(count + apices.size(), extra_value, cloud);
  for (size_t s = 0; s < count; ++s) {
    // Stratified: sample s draws from the s-th equal slice of the area CDF.
    const double target = (static_cast<double>(s) + uni(rng)) / count * total;
    const size_t t = std::min<size_t>(
        std::lower_bound(cdf.begin(), cdf.end(), target) - cdf.begin(), num_tris - 1);
    const double r1 = uni(rng), r2 = uni(rng);
    Eigen::Vector3f p, tangent, n;
    Eigen::Vector2f uv;
    PointOnTriangle(mesh, t, r1, r2, &p, &tangent, &n, &uv);
    PutSurfel(style, base + s, p, tangent, n, uv, cloud);
    if (appearance.specular > 0.0f && cloud->sh_degree >= 1) {
      float* sh = &cloud->sh[static_cast<size_t>(stride) * (base + s)];
      for (int k = 3; k < 12; ++k) sh[k] = appearance.specular * normal(rng);
    }
  }
  for (size_t a = 0; a < apices.size(); ++a) {
    const Eigen::Vector3f n = apices[a].normal.normalized();
    PutSurfel(style, base + count + a, apices[a].position, n.unitOrthogonal(), n, apices[a].uv,
              cloud);
  }
}

}  // namespace instascene
