// common/raster/testing/random_surfels.h: the small random 2DGS scenes the backward-pass tests
// differentiate (surfel_backward_test, tile_backward_test).
#pragma once

#include <cstdint>

#include "common/geometry/camera.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene::testing {

// `count` random surfels 2-4 m in front of SmallCamera(), 3-8 px wide, partly overlapping, with
// random SH of `sh_degree`.
GaussianCloud RandomSurfels(uint64_t seed, int count, int sh_degree);

// A 40x30 camera at the origin looking down +z (fx = fy = 60).
PinholeCamera SmallCamera();

}  // namespace instascene::testing
