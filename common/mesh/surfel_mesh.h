// common/mesh/surfel_mesh.h: 2DGS surfels as small polygon discs, the occluder geometry the
// viewpoint ring and the free-space carving ray-cast against (ALGORITHM.md 7.3 uses a fused mesh;
// discs need no fusion and are exact where the surfels are opaque). Stateless, thread-safe.
#pragma once

#include <cstdint>
#include <vector>

#include "common/geometry/triangle_mesh.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene {

struct SurfelDiscOptions {
  float extent_sigma = 2.0f;  // disc radius along each tangent axis, in that axis' std-devs
  float min_opacity = 0.3f;   // surfels fainter than this are not occluders
  int segments = 6;           // polygon sides (>= 3)
};

// One disc per selected surfel (all surfels when `indices` is empty), in the cloud's frame. 3-scale
// clouds are first reduced with ToSurfels by the caller. `source` (optional) receives, per
// triangle, the index of the Gaussian it came from.
TriangleMesh SurfelDiscs(const GaussianCloud& surfels, const std::vector<uint32_t>& indices,
                         const SurfelDiscOptions& options, std::vector<uint32_t>* source = nullptr);

}  // namespace instascene
