// services/generation/symmetry_scoring.h: how symmetry.cc scores one hypothesis against the
// observed points, for the search over hypotheses in symmetry_search.cc. Internal to the
// generation library; DetectSymmetries (symmetry.h) is the interface.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "common/geometry/point_index.h"
#include "services/generation/symmetry.h"

namespace instascene::generation::symmetry_internal {

// Vertical axis through the least-squares common centre of the horizontal circles the points lie
// on (Kasa fit with one radius per height bin): the axis of a solid of revolution.
Eigen::Vector3f FitAxisPoint(const std::vector<Eigen::Vector3f>& points, const ObjectFrame& frame);

// Accepted before rejected, then by agreement × min(1, 2 × evidence).
bool Better(const SymmetryHypothesis& a, const SymmetryHypothesis& b);

// The vertical plane whose normal is at `theta` from the frame's first horizontal axis, `offset`
// along that normal from the frame's centre.
SymmetryHypothesis VerticalPlane(const ObjectFrame& frame, double theta, float offset);

// Scores *h (agreement, evidence, per-turn counts, accepted) against the points, whose k-d tree
// `index` is.
void ScoreWithIndex(const std::vector<Eigen::Vector3f>& points,
                    const std::vector<Eigen::Vector3f>& normals, const PointIndex3& index,
                    const ObjectFrame& frame, const FreeSpaceGrid& free_space,
                    const SymmetryOptions& options, SymmetryHypothesis* h);

// How far h maps the observed points from observed points over the images it decides
// (normalised; 1 = every decided image contradicts): places a plane or an axis finer than the
// agreement, which is flat over a few millimetres. An image beyond the match distance in front of
// a surfel `surface` (may be null) holds as seen is decided and contradicts too.
double AlignmentCost(const std::vector<Eigen::Vector3f>& points,
                     const std::vector<Eigen::Vector3f>& normals, const PointIndex3& index,
                     const ObjectFrame& frame, const FreeSpaceGrid& free_space,
                     const SymmetryOptions& options, const SymmetryHypothesis& h,
                     const ObservedSurface* surface);

}  // namespace instascene::generation::symmetry_internal
