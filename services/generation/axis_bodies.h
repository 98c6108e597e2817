// services/generation/axis_bodies.h: what the geometric prior's accepted axes hold for
// (GENERATION.md step 6). For each accepted axis: the sources whose images fall in seen-empty space
// (a mug's handle under the body's axis), the parts such sources form clear of the body, the
// surfels beyond the body's radial profile (a neighbour's the segmentation gave the object); from
// them, the instance surfels that are not the object's, and the sources each hypothesis lends no
// images. Stateless and deterministic; thread-safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "common/geometry/point_index.h"
#include "services/generation/free_space.h"
#include "services/generation/geometric_prior.h"
#include "services/generation/object_frame.h"
#include "services/generation/seen_through.h"
#include "services/generation/symmetry.h"

namespace instascene::generation {

// The object's observed surfels as the rules below see them. Every reference outlives the use.
struct InstanceSurfels {
  const std::vector<Eigen::Vector3f>& points;  // instance surfel centres
  const PointIndex3& index;                    // over `points`
  const ObjectFrame& frame;
  const FreeSpaceGrid& free_space;
  const SeenThroughTest* seen_through = nullptr;  // the exact test; null: the grid alone
  // Per surfel: a touching neighbour's label surrounds it; null when not given.
  const std::vector<uint8_t>* neighbour_labelled = nullptr;

  size_t size() const { return points.size(); }
  bool NeighbourLabelled(uint32_t g) const {
    return neighbour_labelled != nullptr && (*neighbour_labelled)[g] != 0;
  }
};

// Per surfel: its images under `h` lie in seen-empty space (more than a quarter of the copies), so
// `h` does not hold for it. `exact`: the grid's answer is confirmed by the seen-through test where
// there is one (a thin object's surface straddles the grid's voxels where views graze it).
std::vector<uint8_t> AsymmetricSources(const SymmetryHypothesis& h, const InstanceSurfels& s,
                                       bool exact);

// What one accepted axis holds for. Every vector is per instance surfel (empty: the rule did not
// apply).
struct AxisBody {
  const SymmetryHypothesis* axis = nullptr;
  std::vector<uint8_t> off;  // AsymmetricSources(*axis), with the handles' parts joined
  // Sources it does not hold for that stick out beyond the body it holds for (a handle).
  std::vector<uint8_t> off_beyond_body;
  // Sources it holds for (their images are not in seen-empty space) that lie beyond the body's
  // profile at their own height: a neighbour's surfels the segmentation gave the object, where
  // no view saw the space around them. (Those it does not hold for within the body's reach
  // are the body's own surfels under a slightly offset axis: a plane may still mirror them.)
  std::vector<uint8_t> beyond_profile;
  // Sources it does not hold for beyond the profile that a touching neighbour's label
  // surrounds: that neighbour's surfels (a handle stands clear of other instances).
  std::vector<uint8_t> neighbours_beyond_profile;
  // Sources it does not hold for beyond the profile, whatever surrounds them.
  std::vector<uint8_t> off_beyond_profile;
};

struct AxisBodies {
  std::vector<AxisBody> bodies;  // one per accepted axis that most of the object agrees with
  std::vector<uint8_t> handle;   // per surfel: part of a handle an axis does not hold for
  // Per surfel: part of a handle's part too small to be one (a neighbour's stray).
  std::vector<uint8_t> small_part;
  int handle_joined = 0;  // sources a handle's part took from what an axis held for
};

// The bodies of the accepted axes among `hypotheses` (which must outlive the result).
AxisBodies AnalyseAxisBodies(const std::vector<SymmetryHypothesis>& hypotheses,
                             const InstanceSurfels& s, const GeometricPriorOptions& options);

// Per surfel: not the object's (a neighbour's surfels beyond a body's profile or reach, the
// patches they belong to, and parts too small to be a handle).
std::vector<uint8_t> ForeignSurfels(const AxisBodies& bodies, const InstanceSurfels& s,
                                    const GeometricPriorOptions& options);

// Per surfel: sources `h` lends no images beyond its own asymmetric ones. Every hypothesis, parts
// too small to be a handle; an axis, those beyond its profile; a plane containing an axis (oriented
// about it only by the parts the axis does not hold for), those and the parts beyond the body that
// the axis does not hold for.
std::vector<uint8_t> SkippedSources(const SymmetryHypothesis& h, const AxisBodies& bodies,
                                    const InstanceSurfels& s, const GeometricPriorOptions& options);

// Per surfel, the body's outer radius about an axis at the surfel's height: the 90th percentile
// (`percent`) of the radii of the `body` surfels over the heights around it (at least 2 `step`s
// either side, more until the window holds `min_count` of them, so that a few strays there stay
// above the percentile), plus one `step`. Infinite everywhere when the body holds fewer than
// `min_count`.
std::vector<float> RadialProfile(const std::vector<float>& height, const std::vector<float>& radial,
                                 const std::vector<uint8_t>& body, float step, int percent = 90,
                                 size_t min_count = 40);

}  // namespace instascene::generation
