// services/generation/symmetry.h: reflective symmetry planes and rotation axes of the observed part
// of an object (GENERATION.md step 4), the hypotheses the geometric prior completes with.
//
// Objects rest on a support under gravity, so only vertical planes (normal orthogonal to up) and
// vertical axes are searched. A hypothesis is scored by transforming every sampled observed surfel:
// its image *agrees* when an observed surfel lies within `match_spacings` instance spacings with a
// compatible normal, *contradicts* when it falls in space real views saw empty (FreeSpaceGrid), and
// is *unknown* otherwise (never observed). agreement = agree / (agree + contradict); evidence =
// (agree + contradict) / scored points. Points within that distance of the plane or axis map onto
// themselves and are not scored. Accepted when agreement >= min_agreement and evidence >=
// min_evidence. An axis is scored per image too: when the images at the multiples of 360 / n
// degrees agree (>= min_agreement) and the others do not, the axis is n-fold (largest such n among
// the divisors of axis_steps), not continuous: a box turned by 45 degrees puts its corners into
// space views saw empty, while its quarter turns map it onto itself. Pure functions, thread-safe.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "services/generation/free_space.h"
#include "services/generation/object_frame.h"
#include "services/generation/observed_surface.h"

namespace instascene::generation {

enum class SymmetryKind { kPlane, kAxis };

struct SymmetryHypothesis {
  SymmetryKind kind = SymmetryKind::kPlane;
  Eigen::Vector3f point = Eigen::Vector3f::Zero();       // on the plane / axis, world frame
  Eigen::Vector3f direction = Eigen::Vector3f::UnitX();  // plane normal / axis direction (unit)
  int copies = 1;  // images per point: 1 for a plane, steps - 1 (or order - 1) for an axis
  // An axis's order: 0 = a solid of revolution (copies every 360 / (copies + 1) degrees); n >= 2 =
  // n-fold (a box: 2 or 4), copies at 360 k / n degrees.
  int order = 0;
  int scored = 0;  // points scored (off the plane / axis)
  int agree = 0, contradict = 0;
  std::vector<int> copy_agree, copy_contradict;  // per image k
  double agreement = 0;                          // agree / (agree + contradict)
  double evidence = 0;                           // (agree + contradict) / (scored * copies)
  bool accepted = false;

  // The k-th image (k in [0, copies)) of a point / of a direction.
  Eigen::Vector3f MapPoint(const Eigen::Vector3f& p, int k) const;
  Eigen::Matrix3f Linear(int k) const;  // rotation (axis) or reflection (plane) matrix
  std::string Describe() const;
};

struct SymmetryOptions {
  double min_agreement = 0.85;
  // A mirror plane needs this agreement as well (an axis min_agreement alone: a mug's handle
  // contradicts the body's axis and its surfels lend no images). Mirror-symmetric shapes agree
  // 0.95 and more, under mask noise too; bodies symmetric but for a part agree 0.86-0.91 where
  // the part's images land in space no view saw (an L-block's arm mirrored behind its bar), and
  // 0.93 rejects those planes. What such a plane also completed (the bar's hidden back) the
  // support part now gives without it (docs/RESULTS.md "Mirror planes that agree 0.86-0.91",
  // "A stricter mirror plane with the support").
  double min_plane_agreement = 0.93;
  double min_evidence = 0.2;
  int plane_angles = 36;   // normal directions over 180 degrees
  int plane_offsets = 21;  // offsets per direction over +- offset_range_radii
  float offset_range_radii = 0.5f;
  int axis_steps = 12;            // revolution sampled every 360 / axis_steps degrees
  float match_spacings = 2.5f;    // agreement distance in instance spacings
  float normal_agreement = 0.5f;  // |cos| between an image's normal and its match's
  int max_points = 1500;          // observed surfels scored (deterministic stride)
  // The best plane is refined over +- refine_steps finer steps (a refine_steps-th of the grid's
  // angle and offset steps) by the alignment cost (symmetry.cc); 0 = the grid's plane.
  int refine_steps = 8;
  // The axis point found by agreement is moved to the least alignment cost nearby (symmetry.cc).
  bool refine_axis = true;
  // The planes' alignment cost counts an image beyond the match distance that stands in front of
  // a seen surfel, where the views looked through (ObservedSurface::InFrontOfSeenSurface), as
  // contradicting, not as unknown: near the object the free-space grid's margin leaves such
  // images unknown, and a plane shifted by 4 mm moved a box's mirrored face 8 mm past its seen
  // one at a lower cost (docs/RESULTS.md "A mirror plane placed against the seen surface"). The
  // axis's refinement does not ask it.
  bool cost_observed_surface = true;
  // A solid of revolution must agree at every turn (AgreesAtEveryTurn); false = the whole's
  // agreement alone decides.
  bool revolution_every_turn = true;
  int min_turn_decided = 10;  // a turn decided for fewer images does not reject (AgreesAtEveryTurn)
  // An n-fold order needs its worst turn to agree better than every other turn (DiscreteOrder).
  bool order_outagrees_other_turns = true;
};

// The best plane and the best axis found (each reported even when rejected, so the manifest can
// say what was tried), accepted first. `points` / `normals`: the observed instance surfels;
// `observed_surface` (may be null: not used) the test of SymmetryOptions::cost_observed_surface.
std::vector<SymmetryHypothesis> DetectSymmetries(const std::vector<Eigen::Vector3f>& points,
                                                 const std::vector<Eigen::Vector3f>& normals,
                                                 const ObjectFrame& frame,
                                                 const FreeSpaceGrid& free_space,
                                                 const SymmetryOptions& options,
                                                 const ObservedSurface* observed_surface = nullptr);

// Whether no turn of an axis agrees less than min_agreement beyond chance: for each turn decided
// for at least min_turn_decided images, the one-sided 95 % Wilson upper bound of its agree /
// decided must reach min_agreement. A continuous axis (a solid of revolution) must pass, as each
// turn of an n-fold group must agree on its own: a partly seen box lands most images of its turns
// in unseen space, its overall agreement passes, and the few decided images of a turn that swings
// its corners out disagree (seed 44's box_7: 11 of 16; docs/RESULTS.md "A solid of revolution
// agrees at every turn").
bool AgreesAtEveryTurn(const SymmetryHypothesis& hypothesis, const SymmetryOptions& options);

// The largest n (a divisor of the axis's steps) whose images at 360 k / n degrees agree while the
// other images do not; 0 when there is none (a solid of revolution, or no symmetry). Every turn of
// the group must agree on its own, within 0.1 of the group's best: a nearly square box's quarter
// turns overhang its shorter faces by less than the match distance and agree at 0.83-0.86 while
// its half turn agrees at 1.00; completed by quarter turns it stands past its faces. And no other
// turn decided for min_turn_decided images may agree as well as the group's worst
// (order_outagrees_other_turns): a half-seen rectangular box's third turns agreed 0.89 / 0.88 and
// passed as a 3-fold axis while its half turn agreed 0.99 (docs/RESULTS.md "An n-fold axis
// agrees better than every other turn").
int DiscreteOrder(const SymmetryHypothesis& hypothesis, const SymmetryOptions& options);

// Scores one hypothesis in place (exposed for tests).
void ScoreHypothesis(const std::vector<Eigen::Vector3f>& points,
                     const std::vector<Eigen::Vector3f>& normals, const ObjectFrame& frame,
                     const FreeSpaceGrid& free_space, const SymmetryOptions& options,
                     SymmetryHypothesis* hypothesis);

}  // namespace instascene::generation
