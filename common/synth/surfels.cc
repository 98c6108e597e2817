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
  const float log_sigma = std::log(sigma);
  const float opacity_logit = std::log(sampling.opacity / (1.0f - sampling.opacity));
  const Eigen::Vector3f light = sampling.light_dir.normalized();
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  const size_t base = cloud->size();
  const size_t added = count + apices.size();
  const int stride = cloud->sh_stride();
  // Grow every array by `added` (extras keep their values; new entries get extra_value).
  cloud->positions.resize(3 * (base + added));
  cloud->log_scales.resize(2 * (base + added));
  cloud->rotations.resize(4 * (base + added));
  cloud->opacity_logits.resize(base + added);
  cloud->sh.resize(static_cast<size_t>(stride) * (base + added), 0.0f);
  for (ExtraChannel& e : cloud->extras) e.values.resize(base + added, extra_value);
  // Surfel i at p, tangent tu, unit normal n; its colour from the texture at uv, lit.
  auto put = [&](size_t i, const Eigen::Vector3f& p, const Eigen::Vector3f& tu,
                 const Eigen::Vector3f& n, const Eigen::Vector2f& uv) {
    const Eigen::Vector3f tv = n.cross(tu);
    Eigen::Matrix3d frame;
    frame << tu.cast<double>(), tv.cast<double>(), n.cast<double>();
    const Eigen::Vector4d q = QuaternionWxyzFromRotation(frame);
    const float shade = 0.45f + 0.55f * std::abs(n.dot(light));
    const Eigen::Vector3f rgb = (ShadeUv(appearance, uv) * shade).cwiseMin(1.0f);
    for (int a = 0; a < 3; ++a) cloud->positions[3 * i + a] = p[a];
    cloud->log_scales[2 * i] = cloud->log_scales[2 * i + 1] = log_sigma;
    for (int a = 0; a < 4; ++a) cloud->rotations[4 * i + a] = static_cast<float>(q[a]);
    cloud->opacity_logits[i] = opacity_logit;
    for (int c = 0; c < 3; ++c) cloud->sh[static_cast<size_t>(stride) * i + c] = RgbToSh0(rgb[c]);
  };
  for (size_t s = 0; s < count; ++s) {
    // Stratified: sample s draws from the s-th equal slice of the area CDF.
    const double target = (static_cast<double>(s) + uni(rng)) / count * total;
    const size_t t = std::min<size_t>(
        std::lower_bound(cdf.begin(), cdf.end(), target) - cdf.begin(), num_tris - 1);
    const auto& tri = mesh.triangles[t];
    double r1 = uni(rng), r2 = uni(rng);
    if (r1 + r2 > 1.0) {
      r1 = 1.0 - r1;
      r2 = 1.0 - r2;
    }
    const float b1 = static_cast<float>(r1), b2 = static_cast<float>(r2), b0 = 1.0f - b1 - b2;
    const Eigen::Vector3f p =
        b0 * mesh.vertices[tri[0]] + b1 * mesh.vertices[tri[1]] + b2 * mesh.vertices[tri[2]];
    const Eigen::Vector3f e1 = mesh.vertices[tri[1]] - mesh.vertices[tri[0]];
    const Eigen::Vector3f n = e1.cross(mesh.vertices[tri[2]] - mesh.vertices[tri[0]]).normalized();
    Eigen::Vector2f uv = Eigen::Vector2f::Zero();
    if (mesh.uvs.size() == mesh.vertices.size())
      uv = b0 * mesh.uvs[tri[0]] + b1 * mesh.uvs[tri[1]] + b2 * mesh.uvs[tri[2]];
    put(base + s, p, e1.normalized(), n, uv);
    if (appearance.specular > 0.0f && cloud->sh_degree >= 1) {
      float* sh = &cloud->sh[static_cast<size_t>(stride) * (base + s)];
      for (int k = 3; k < 12; ++k) sh[k] = appearance.specular * normal(rng);
    }
  }
  for (size_t a = 0; a < apices.size(); ++a) {
    const Eigen::Vector3f n = apices[a].normal.normalized();
    put(base + count + a, apices[a].position, n.unitOrthogonal(), n, apices[a].uv);
  }
}

}  // namespace instascene
