// common/synth/surfels.h: turning meshes into textured 2DGS surfels.
//
// Surfels are sampled uniformly by area (stratified per triangle so coverage has no large holes),
// oriented along the surface, sized from the sampling density so neighbours overlap into an
// opaque surface, and coloured by a procedural texture in the mesh's UV space with baked diffuse
// lighting. Deterministic from the caller's RNG. Not thread-safe per RNG.
#pragma once

#include <cstdint>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "common/geometry/triangle_mesh.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene {

enum class TexturePattern { kSolid, kStripes, kChecker, kDots, kNoise };

struct Appearance {
  Eigen::Vector3f color_a = Eigen::Vector3f(0.8f, 0.2f, 0.2f);  // linear RGB in [0, 1]
  Eigen::Vector3f color_b = Eigen::Vector3f(0.9f, 0.9f, 0.9f);
  TexturePattern pattern = TexturePattern::kSolid;
  float frequency = 6.0f;  // pattern repeats per unit UV
  float specular = 0.0f;   // > 0 adds SH degree-1 view dependence of this magnitude
  uint32_t noise_seed = 0;
};

// Texture colour at a UV coordinate (before lighting).
Eigen::Vector3f ShadeUv(const Appearance& appearance, const Eigen::Vector2f& uv);

struct SurfelSampling {
  float opacity = 0.95f;      // surfel opacity
  float scale_factor = 1.1f;  // surfel sigma = scale_factor * sqrt(area / count)
  Eigen::Vector3f light_dir = Eigen::Vector3f(0.3f, -0.4f, 0.87f);  // baked diffuse light (world)
};

// A point where the surface closes to a tip (a cone's apex), with the surfel's normal there and
// the mesh's UV at it.
struct SurfelApex {
  Eigen::Vector3f position = Eigen::Vector3f::Zero();
  Eigen::Vector3f normal = Eigen::Vector3f::UnitZ();
  Eigen::Vector2f uv = Eigen::Vector2f::Zero();
};

// Appends `count` surfels on `mesh` (world frame) to `cloud` (must be a 2-scale cloud of SH degree
// >= 1 when appearance.specular > 0), then one surfel of the same size on each of `apices`. Area
// sampling leaves a sharp tip bare (the nearest of N surfels stands about 1 / sqrt(N) of the slant
// below a cone's apex), where a model trained on photographs places surfels to draw it. Extra
// channels of `cloud` get `extra_value` for new surfels. The apices draw nothing from `rng`.
void AppendSurfels(const TriangleMesh& mesh, size_t count, const Appearance& appearance,
                   const SurfelSampling& sampling, std::mt19937_64& rng, GaussianCloud* cloud,
                   float extra_value = 0.0f, const std::vector<SurfelApex>& apices = {});

}  // namespace instascene
