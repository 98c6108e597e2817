// common/synth/random_objects.h: the synthetic scene generator's random draws (internal to
// common/synth): the seeded engine, object shapes (symmetric and not) and their appearances.
// Every draw consumes the engine in a fixed order: scenes are reproducible from their seed.
#pragma once

#include <random>

#include <Eigen/Core>

#include "common/synth/primitives.h"
#include "common/synth/surfels.h"

namespace instascene {

struct Rng {
  std::mt19937_64 engine;
  float Uniform(float lo, float hi) {
    return std::uniform_real_distribution<float>(lo, hi)(engine);
  }
  int Int(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(engine); }
};

// A saturated colour (HSV with saturation 0.45-0.9 and value 0.5-0.95).
Eigen::Vector3f RandomColor(Rng& rng);

// One of the eight symmetric shape kinds with its sizes (metres).
ShapeSpec RandomShape(Rng& rng);

// A mug with a handle, an L-block or an irregular block.
ShapeSpec AsymmetricShape(Rng& rng);

// A textured two-colour appearance (never a flat colour); specular only with SH degree >= 1.
Appearance RandomAppearance(Rng& rng, int sh_degree);

}  // namespace instascene
