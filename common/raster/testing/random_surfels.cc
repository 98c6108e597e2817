#include "common/raster/testing/random_surfels.h"

#include <cmath>
#include <random>

namespace instascene::testing {

GaussianCloud RandomSurfels(uint64_t seed, int count, int sh_degree) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  GaussianCloud cloud;
  cloud.num_scales = 2;
  cloud.sh_degree = sh_degree;
  cloud.Resize(count);
  for (int g = 0; g < count; ++g) {
    cloud.positions[3 * g] = 0.35f * u(rng);
    cloud.positions[3 * g + 1] = 0.25f * u(rng);
    cloud.positions[3 * g + 2] = 3.0f + u(rng);
    cloud.log_scales[2 * g] = std::log(0.07f + 0.02f * u(rng));
    cloud.log_scales[2 * g + 1] = std::log(0.07f + 0.02f * u(rng));
    for (int k = 0; k < 4; ++k) cloud.rotations[4 * g + k] = u(rng) + (k == 0 ? 1.5f : 0.0f);
    cloud.opacity_logits[g] = 0.5f + 0.8f * u(rng);
    for (int k = 0; k < cloud.sh_stride(); ++k) {
      cloud.sh[cloud.sh_stride() * g + k] = (k < 3 ? 0.8f : 0.3f) * u(rng);
    }
  }
  return cloud;
}

PinholeCamera SmallCamera() {
  PinholeCamera c;
  c.width = 40;
  c.height = 30;
  c.fx = c.fy = 60;
  c.cx = 20;
  c.cy = 15;
  return c;
}

}  // namespace instascene::testing
