// services/generation/candidate_filter.h: the test every surfel a completion prior proposes must
// pass before it joins the object (GENERATION.md step 6): on or above the support, not in space
// the views saw empty (the carved grid, then the exact seen-through test), not within the cover
// distance of an observed or an already added surfel, not off the observed surface's side. Keeps
// the accepted candidates in order and counts the rejections. Not thread-safe (one per object).
#pragma once

#include <cstdint>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "common/geometry/point_index.h"
#include "services/generation/free_space.h"
#include "services/generation/geometric_prior.h"
#include "services/generation/object_frame.h"
#include "services/generation/observed_surface.h"
#include "services/generation/seen_through.h"
#include "services/generation/support_completion.h"

namespace instascene::generation {

// Why candidates were refused (the prior's report, "rejected").
struct CandidateRejections {
  int observed_free = 0;         // in space the views saw empty
  int already_covered = 0;       // within the cover distance of a surfel
  int below_support = 0;         // under the support plane
  int off_observed_surface = 0;  // on the wrong side of the observed surface
  int axis_cap_open_above = 0;   // an axis cap's disc point with no surface above it
};

class CandidateFilter {
 public:
  // Every pointer and reference outlives the filter; `seen_through` may be null (grid only).
  CandidateFilter(const ObjectFrame& frame, const PointIndex3& observed,
                  const ObservedSurface& observed_surface, const FreeSpaceGrid& free_space,
                  const SeenThroughTest* seen_through, const GeometricPriorOptions& options);

  // Adds `c` to the accepted candidates unless a test refuses it.
  void Consider(const SurfelCandidate& c);

  const std::vector<SurfelCandidate>& added() const { return added_; }
  // The cover distance (scene units): candidates closer to a surfel are redundant.
  float cover() const { return cover_; }
  CandidateRejections& rejected() { return rejected_; }
  const CandidateRejections& rejected() const { return rejected_; }

 private:
  // Positions already holding an added surfel, hashed on a grid of the cover distance (observed
  // ones use the k-d tree).
  bool Covered(const Eigen::Vector3f& p) const;
  Eigen::Vector3i Cell(const Eigen::Vector3f& p) const;

  const ObjectFrame& frame_;
  const PointIndex3& observed_;
  const ObservedSurface& observed_surface_;
  const FreeSpaceGrid& free_space_;
  const SeenThroughTest* seen_through_;
  const GeometricPriorOptions& options_;
  float cover_;
  std::unordered_map<int64_t, std::vector<Eigen::Vector3f>> cells_;
  std::vector<SurfelCandidate> added_;
  CandidateRejections rejected_;
};

}  // namespace instascene::generation
