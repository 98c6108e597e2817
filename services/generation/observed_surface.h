// services/generation/observed_surface.h: does a completion candidate contradict the observed
// surface beside it? (GENERATION.md step 4). Each observed surfel is a small piece of surface
// whose normal is turned to the side the real views saw it from. A candidate within
// `lateral_spacings` of such a surfel along its plane that stands more than `front_spacings` in
// front of it lies where those views looked through to the surfel; one more than
// `behind_spacings` behind it (and within max(front, behind) + lateral spacings of it: a thicker
// solid's far side is not asked) lies inside a wall the capture saw from one side only (a mug's
// cavity behind its seen outer wall), not on it. Either contradicts the observation, so the prior
// refuses it. The free-space tests cannot: near the object the model's own blurred surfels stop
// their rays (RESULTS.md "Free-space violations: candidates off the observed surface").
// Immutable after construction; thread-safe reads.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "absl/status/status.h"
#include "common/geometry/point_index.h"
#include "services/generation/seen_through.h"

namespace instascene::generation {

struct ObservedSurfaceOptions {
  float front_spacings = 0.75f;   // in front of a seen surfel by more than this (0 = test off) ...
  float behind_spacings = 1.5f;   // ... or behind it by more than this (0 = not tested) ...
  float lateral_spacings = 2.0f;  // ... and within this of it along its plane: contradicted
  absl::Status Validate() const;
};

// The unit normals turned to the side the real views saw each surfel from
// (SeenThroughTest::SeenSide); away from `center` where no view sees the surfel or `seen` is null.
std::vector<Eigen::Vector3f> SeenSideNormals(const std::vector<Eigen::Vector3f>& points,
                                             const std::vector<Eigen::Vector3f>& normals,
                                             const SeenThroughTest* seen,
                                             const Eigen::Vector3f& center);

class ObservedSurface {
 public:
  // `index` holds the observed surfels' centres (not owned; must outlive this), `normals` their
  // unit normals (either sign), turned by SeenSideNormals(`seen`, `center`) when the test is on;
  // `spacing` is their median nearest-neighbour distance.
  ObservedSurface(const PointIndex3* index, const std::vector<Eigen::Vector3f>& normals,
                  const SeenThroughTest* seen, const Eigen::Vector3f& center, float spacing,
                  const ObservedSurfaceOptions& options);
  bool Contradicts(const Eigen::Vector3f& p) const { return Test(p, true); }
  // The first half of the test only, asked of the surfels within front + lateral spacings: p
  // stands in front of a seen surfel, where the views looked through. (Behind a surfel is no
  // contradiction at a convex corner's unseen face: its points lie behind the seen neighbouring
  // face's edge surfels, within their lateral reach.)
  bool InFrontOfSeenSurface(const Eigen::Vector3f& p) const { return Test(p, false); }

 private:
  bool Test(const Eigen::Vector3f& p, bool behind) const;

  const PointIndex3* index_;                   // null: the test is off
  std::vector<Eigen::Vector3f> seen_normals_;  // SeenSideNormals of the index's points
  float front_ = 0, behind_ = 0, lateral_ = 0, search_ = 0;
};

}  // namespace instascene::generation
