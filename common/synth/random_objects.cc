#include "common/synth/random_objects.h"

#include <cmath>

namespace instascene {

Eigen::Vector3f RandomColor(Rng& rng) {
  // Saturated, varied colours via HSV.
  const float h = rng.Uniform(0, 6), s = rng.Uniform(0.45f, 0.9f), v = rng.Uniform(0.5f, 0.95f);
  const float c = v * s, x = c * (1 - std::abs(std::fmod(h, 2.0f) - 1)), m = v - c;
  Eigen::Vector3f rgb;
  switch (static_cast<int>(h)) {
    case 0:
      rgb = {c, x, 0};
      break;
    case 1:
      rgb = {x, c, 0};
      break;
    case 2:
      rgb = {0, c, x};
      break;
    case 3:
      rgb = {0, x, c};
      break;
    case 4:
      rgb = {x, 0, c};
      break;
    default:
      rgb = {c, 0, x};
      break;
  }
  return rgb + Eigen::Vector3f::Constant(m);
}

ShapeSpec RandomShape(Rng& rng) {
  ShapeSpec s;
  s.kind = static_cast<ShapeKind>(rng.Int(0, 7));
  const float r = rng.Uniform(0.035f, 0.10f);
  switch (s.kind) {
    case ShapeKind::kBox:
      s.size = {rng.Uniform(0.06f, 0.2f), rng.Uniform(0.05f, 0.14f), rng.Uniform(0.04f, 0.22f)};
      break;
    case ShapeKind::kSphere:
      s.size = {r, r, 2 * r};
      break;
    case ShapeKind::kTorus:
      s.size = {r, 0.35f * r, 0.7f * r};
      break;
    case ShapeKind::kBottle:
      s.size = {0.7f * r, 0, rng.Uniform(0.16f, 0.28f)};
      break;
    case ShapeKind::kCup:
      s.size = {0.8f * r, 0, rng.Uniform(0.07f, 0.12f)};
      break;
    case ShapeKind::kBowl:
      s.size = {1.3f * r, 0, 0.6f * r};
      break;
    default:
      s.size = {r, 0, rng.Uniform(0.06f, 0.2f)};
      break;
  }
  return s;
}

ShapeSpec AsymmetricShape(Rng& rng) {
  ShapeSpec s;
  s.kind = static_cast<ShapeKind>(
      rng.Int(static_cast<int>(ShapeKind::kMug), static_cast<int>(ShapeKind::kIrregular)));
  if (s.kind == ShapeKind::kMug) {
    s.size = {rng.Uniform(0.035f, 0.06f), 0, rng.Uniform(0.08f, 0.12f)};
  } else {
    s.size = {rng.Uniform(0.1f, 0.2f), rng.Uniform(0.08f, 0.14f), rng.Uniform(0.06f, 0.16f)};
  }
  return s;
}

Appearance RandomAppearance(Rng& rng, int sh_degree) {
  Appearance a;
  a.color_a = RandomColor(rng);
  a.color_b = rng.Uniform(0, 1) < 0.5f ? RandomColor(rng) : Eigen::Vector3f(0.92f, 0.92f, 0.9f);
  a.pattern = static_cast<TexturePattern>(rng.Int(1, 4));  // textured, never a flat colour
  a.frequency = rng.Uniform(3.0f, 10.0f);
  a.noise_seed = static_cast<uint32_t>(rng.engine());
  a.specular = sh_degree >= 1 && rng.Uniform(0, 1) < 0.4f ? 0.08f : 0.0f;
  return a;
}

}  // namespace instascene
