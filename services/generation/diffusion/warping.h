// services/generation/diffusion/warping.h: geometry-aware warping of known views into target
// views (ALGORITHM.md 7.7; the prototype's warp_known_target_views), in pixel space; the latent
// grid is the same operation at the latent's resolution (a camera scaled by 1/8).
// Per target pixel: the first hit X of its ray on the instance mesh (Embree); back-face culling
// keeps it only when 0 < n . (-ray) (the geometric normal of the hit faces the target); the known
// views are tried in the given order (nearest azimuth first): X must face the known camera too
// (cosine >= min_known_cosine), project inside the known image and be visible there (the known
// camera's ray towards X first hits the mesh within `visibility_tolerance` of |X - o|); the first
// known view that sees X gives the value (bilinear at the projection). Pixels no known view sees
// are left unwritten (the sampler keeps its own noise there). Deterministic; rows in parallel.
// Thread-safe.
#pragma once

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/mesh/ray_caster.h"

namespace instascene::generation::diffusion {

struct KnownView {
  PinholeCamera camera;
  std::vector<float> values;  // HxWxC
};

struct WarpOptions {
  int channels = 3;
  float visibility_tolerance = 0.01f;  // relative to the distance |X - o|
  // The known view must see X at least this frontally (cosine between the hit's normal and the
  // direction to the known camera, 0.3 = 72.5 degrees): grazing samples mix the silhouette with
  // what lies behind (warping_test: 27 dB at 0.1, 70 dB at 0.3 against a direct render).
  float min_known_cosine = 0.3f;
};

struct WarpResult {
  std::vector<float> values;   // HxWxC of the target, 0 where unwritten
  std::vector<uint8_t> known;  // HxW: 1 where a known view wrote the pixel
  // HxW: depth (z in the target camera) of the ray's first hit on the instance mesh, front- or
  // back-facing, written or not; 0 where the ray misses the mesh.
  std::vector<float> depth;
  int64_t written = 0, missed = 0, back_facing = 0, unseen = 0;  // pixel counts
};

// InvalidArgument when a known view's values do not match its camera and the channel count.
absl::StatusOr<WarpResult> WarpIntoTarget(const RayCaster& mesh,
                                          const std::vector<KnownView>& known,
                                          const PinholeCamera& target, const WarpOptions& options);

}  // namespace instascene::generation::diffusion
