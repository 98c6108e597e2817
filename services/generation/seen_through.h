// services/generation/seen_through.h: the exact free-space test of a completion candidate (did
// some real view see through this point?), GENERATION.md step 4. A view saw through p when every
// ray of p's one-pixel footprint (through p and p moved by half a pixel left, right, up and down
// at its depth) keeps at least half its transmittance until `tolerance` beyond p. The
// transmittance is the capture's own model traced along the ray: every surfel disc the ray
// crosses (Embree) attenuates it by the Gaussian's alpha at the crossing, in the order of the
// crossings (not the rasteriser's order by centre depth, which lets a large table surfel hide an
// object's inside). This is the evaluation's test (EVALUATION.md) with the model in place of the
// true surfaces. Surfels count within 1 sigma of their centres: a model's silhouettes lie about
// a sigma outside the true ones, and 2-sigma discs left 6x the violations (RESULTS.md
// "Free-space violations"). A second, stricter count takes surfels only within `core_sigma` of
// their centres (their own discs: the rim of a blurred silhouette no longer blocks) and needs
// `core_views` views to agree: a ray slipping through a gap between those smaller discs is one
// view's accident, the space beside a blurred rim is seen by many. A third, the rim count, takes
// one view whose rays are stopped by nothing farther than `rim_depth_radii` in front of p at 1
// sigma and by nothing at `core_sigma`: they pass beside the object's own blurred rim next to p,
// not through a gap in a surface far in front of it (a hidden back side seen through the front).
// Immutable after Create; thread-safe reads.
#pragma once

#include <array>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/mesh/ray_caster.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene::generation {

// p's one-pixel footprint in camera c: p and p moved by half a pixel left, right, up and down at
// its depth (world frame). False, and nothing written, when c does not see p (behind it or off
// the image). The evaluation's free-space test (completion_eval.cc) uses the same footprint.
bool PixelFootprint(const PinholeCamera& c, const Eigen::Vector3f& p,
                    std::array<Eigen::Vector3f, 5>* points);

struct SeenThroughOptions {
  float min_opacity = 0.05f;      // fainter surfels are ignored (they barely attenuate)
  float extent_sigma = 1.0f;      // a surfel attenuates rays within this many sigmas of its centre
  float blocked_below = 0.5f;     // a ray whose transmittance falls below this is stopped
  float tolerance_radii = 0.02f;  // surfaces nearer than this behind p do not see through it
  int max_crossings = 64;         // per ray; a ray crossing more is taken as stopped
  float core_sigma = 0.5f;        // the stricter count: discs this many sigmas wide ...
  int core_views = 2;             // ... and this many views must see through (0 = off)
  // The rim count: one view sees through p when its rays reach within this many radii of p at
  // 1 sigma and past p at core_sigma (0 = off; needs core_views > 0 for the core discs).
  float rim_depth_radii = 0.2f;
  absl::Status Validate() const;
};

class SeenThroughTest {
 public:
  // `scene` holds every surfel of the capture (2-scale), `cameras` the real views; `radius` is the
  // object's, which scales the tolerance.
  static absl::StatusOr<SeenThroughTest> Create(const std::vector<PinholeCamera>& cameras,
                                                const GaussianCloud& scene, float radius,
                                                const SeenThroughOptions& options);

  // The number of real views that saw through p, counted up to `enough` (with the core discs:
  // the stricter count).
  int ViewsSeeingThrough(const Eigen::Vector3f& p, int enough = 1, bool core = false) const;
  // One view through the extent_sigma discs, or core_views views through the core discs.
  bool SeenThrough(const Eigen::Vector3f& p) const;
  // The transmittance left along origin + t * direction (unit) for t in [0, t_far].
  float Transmittance(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction, float t_far,
                      bool core = false) const;
  float tolerance() const { return tolerance_; }
  // +1 / -1: the side of the plane (p, n) the real views that see p look from (the majority,
  // weighted by |cos|); 0 when no view sees p.
  int SeenSide(const Eigen::Vector3f& p, const Eigen::Vector3f& n) const;

 private:
  struct Surfel {
    Eigen::Vector3f center, u, v;  // tangent axes scaled by 1 / sigma
    float opacity = 0;
  };
  // Discs of every surfel at opacity >= min_opacity, each triangle mapped to its surfel.
  struct Discs {
    std::unique_ptr<RayCaster> caster;
    std::vector<uint32_t> triangle_surfel;  // triangle -> index into surfels_
  };
  bool ViewSeesThrough(const PinholeCamera& camera, const Eigen::Vector3f& p, bool core) const;
  // The rim count's test of one view.
  bool ViewSeesPastRim(const PinholeCamera& camera, const Eigen::Vector3f& p) const;
  std::vector<PinholeCamera> cameras_;
  Discs discs_, core_discs_;  // at extent_sigma / at core_sigma (none when core_views = 0)
  std::vector<Surfel> surfels_;
  SeenThroughOptions options_;
  float tolerance_ = 0;
  float rim_depth_ = 0;
};

}  // namespace instascene::generation
