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
// "Free-space violations").
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
  absl::Status Validate() const;
};

class SeenThroughTest {
 public:
  // `scene` holds every surfel of the capture (2-scale), `cameras` the real views; `radius` is the
  // object's, which scales the tolerance.
  static absl::StatusOr<SeenThroughTest> Create(const std::vector<PinholeCamera>& cameras,
                                                const GaussianCloud& scene, float radius,
                                                const SeenThroughOptions& options);

  // The number of real views that saw through p, counted up to `enough`.
  int ViewsSeeingThrough(const Eigen::Vector3f& p, int enough = 1) const;
  bool SeenThrough(const Eigen::Vector3f& p) const { return ViewsSeeingThrough(p) > 0; }
  // The transmittance left along origin + t * direction (unit) for t in [0, t_far].
  float Transmittance(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction,
                      float t_far) const;
  float tolerance() const { return tolerance_; }

 private:
  struct Surfel {
    Eigen::Vector3f center, u, v;  // tangent axes scaled by 1 / sigma
    float opacity = 0;
  };
  bool ViewSeesThrough(const PinholeCamera& camera, const Eigen::Vector3f& p) const;
  std::vector<PinholeCamera> cameras_;
  std::unique_ptr<RayCaster> discs_;
  std::vector<uint32_t> triangle_surfel_;  // disc triangle -> index into surfels_
  std::vector<Surfel> surfels_;
  SeenThroughOptions options_;
  float tolerance_ = 0;
};

}  // namespace instascene::generation
