// DetectSymmetries (symmetry.h): the search over mirror planes and vertical axes, each candidate
// scored by symmetry.cc (symmetry_scoring.h).
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <memory>

#include "services/generation/symmetry.h"
#include "services/generation/symmetry_scoring.h"

namespace instascene::generation {
namespace {

using symmetry_internal::AlignmentCost;
using symmetry_internal::Better;
using symmetry_internal::FitAxisPoint;
using symmetry_internal::ScoreWithIndex;
using symmetry_internal::VerticalPlane;

constexpr double kPi = 3.14159265358979323846;

// The observed points (subsampled to options.max_points) the hypotheses are scored on.
struct ScoredPoints {
  const std::vector<Eigen::Vector3f>& points;
  const std::vector<Eigen::Vector3f>& normals;
  const PointIndex3& index;
  const ObjectFrame& frame;
  const FreeSpaceGrid& free_space;
  const SymmetryOptions& options;
  // The observed surface the planes' alignment cost asks (null: not asked). Not the axis's:
  // asked there it placed cups' axes worse (their mean largest extent error 0.0034 -> 0.0067 over
  // 45 scenes; docs/RESULTS.md "A mirror plane placed against the seen surface").
  const ObservedSurface* surface;

  void Score(SymmetryHypothesis* h) const {
    ScoreWithIndex(points, normals, index, frame, free_space, options, h);
  }
};

// The best vertical mirror plane: every (angle, offset) pair of the grid, scored in parallel into
// fixed slots (thread-count free), then refined by the alignment cost over a finer local grid.
SymmetryHypothesis BestPlane(const ScoredPoints& in) {
  const SymmetryOptions& options = in.options;
  const ObjectFrame& frame = in.frame;
  const int angles = std::max(1, options.plane_angles),
            offsets = std::max(1, options.plane_offsets);
  std::vector<SymmetryHypothesis> planes(static_cast<size_t>(angles) * offsets);
  tbb::parallel_for(size_t{0}, planes.size(), [&](size_t slot) {
    const int a = static_cast<int>(slot) / offsets, o = static_cast<int>(slot) % offsets;
    const double theta = kPi * a / angles;
    const float offset = offsets == 1 ? 0.0f
                                      : options.offset_range_radii * frame.radius *
                                            (2.0f * o / (offsets - 1) - 1.0f);
    SymmetryHypothesis& h = planes[slot];
    h = VerticalPlane(frame, theta, offset);
    in.Score(&h);
  });
  SymmetryHypothesis best_plane = planes[0];
  for (const SymmetryHypothesis& h : planes) {
    if (Better(h, best_plane)) best_plane = h;
  }
  // The grid's steps (180 / plane_angles degrees, a tenth of the offset range) leave the plane up
  // to half a step off, and a mirror doubles the angle: a mug's handle mirrored 5 degrees off
  // lands a centimetre beside it. Refined by the alignment cost over a finer local grid.
  if (options.refine_steps <= 0) return best_plane;
  const int n = options.refine_steps;
  const double angle_step = kPi / angles / n;
  const float offset_step =
      (offsets == 1 ? 0.1f : 2.0f / (offsets - 1)) * options.offset_range_radii * frame.radius / n;
  const Eigen::Matrix3f basis = frame.Basis();
  const double theta0 =
      std::atan2(best_plane.direction.dot(basis.col(1)), best_plane.direction.dot(basis.col(0)));
  const float offset0 = (best_plane.point - frame.center).dot(best_plane.direction);
  std::vector<SymmetryHypothesis> fine(static_cast<size_t>(2 * n + 1) * (2 * n + 1));
  std::vector<double> cost(fine.size());
  tbb::parallel_for(size_t{0}, fine.size(), [&](size_t slot) {
    const int da = static_cast<int>(slot) / (2 * n + 1) - n;
    const int doff = static_cast<int>(slot) % (2 * n + 1) - n;
    fine[slot] = VerticalPlane(frame, theta0 + da * angle_step, offset0 + doff * offset_step);
    cost[slot] = AlignmentCost(in.points, in.normals, in.index, frame, in.free_space, options,
                               fine[slot], in.surface);
  });
  const size_t best = static_cast<size_t>(std::min_element(cost.begin(), cost.end()) -
                                          cost.begin());  // first minimum: deterministic
  SymmetryHypothesis refined = fine[best];
  in.Score(&refined);
  if (refined.accepted || !best_plane.accepted) best_plane = refined;
  return best_plane;
}

// Local searches for a vertical axis's point, on a subsample (every third scored point) with
// fewer copies; a few millimetres matter for thin rings (tori).
class AxisSearch {
 public:
  explicit AxisSearch(const ScoredPoints& in) : in_(in) {
    for (size_t i = 0; i < in.points.size(); i += 3) {
      points_.push_back(in.points[i]);
      normals_.push_back(in.normals[i]);
    }
    index_ = std::make_unique<PointIndex3>(points_);
  }

  // The axis point maximising the coarse score (agreement × min(1, 2 × evidence)) among shifts
  // of `start` with `order` turns (0: six).
  Eigen::Vector3f Search(const Eigen::Vector3f& start, int order, int reach,
                         float step_radii) const {
    return BestShift(start, order > 0 ? order : 6, reach, step_radii,
                     [&](const SymmetryOptions& coarse, SymmetryHypothesis* h) {
                       ScoreWithIndex(points_, normals_, *index_, in_.frame, in_.free_space, coarse,
                                      h);
                       return h->agreement * std::min(1.0, 2 * h->evidence);
                     });
  }

  // Agreement counts images within the match distance and is flat over millimetres: a mug's
  // handle pulls the circle fit towards itself and the search keeps it there (a body revolved
  // about an axis 3 mm off stands 6 mm proud of itself on the far side). The point with the
  // least alignment cost (as for the planes, without the observed surface) over the coarse
  // sample.
  Eigen::Vector3f Refine(const Eigen::Vector3f& start, int reach, float step_radii) const {
    return BestShift(start, 6, reach, step_radii,
                     [&](const SymmetryOptions& coarse, SymmetryHypothesis* h) {
                       return -AlignmentCost(points_, normals_, *index_, in_.frame, in_.free_space,
                                             coarse, *h, nullptr);
                     });
  }

 private:
  // The shift of `start` by (dx, dy) x step_radii radii, |dx|, |dy| <= reach, with the highest
  // `value` (scored in parallel into fixed slots; the first maximum, the start winning ties) on
  // the coarse sample with `steps` turns.
  template <typename Value>
  Eigen::Vector3f BestShift(const Eigen::Vector3f& start, int steps, int reach, float step_radii,
                            Value&& value) const {
    const ObjectFrame& frame = in_.frame;
    const Eigen::Matrix3f basis = frame.Basis();
    SymmetryOptions coarse = in_.options;
    coarse.axis_steps = steps;
    const int side = 2 * reach + 1;
    std::vector<SymmetryHypothesis> shifted(static_cast<size_t>(side) * side);
    std::vector<double> values(shifted.size());
    tbb::parallel_for(size_t{0}, shifted.size(), [&](size_t slot) {
      const int dx = static_cast<int>(slot) % side - reach;
      const int dy = static_cast<int>(slot) / side - reach;
      SymmetryHypothesis& h = shifted[slot];
      h.kind = SymmetryKind::kAxis;
      h.direction = frame.up;
      h.point = start + step_radii * frame.radius * (dx * basis.col(0) + dy * basis.col(1));
      h.copies = coarse.axis_steps - 1;
      values[slot] = value(coarse, &h);
    });
    size_t best = shifted.size() / 2;  // the start itself
    for (size_t k = 0; k < shifted.size(); ++k) {
      if (values[k] > values[best]) best = k;
    }
    return shifted[best].point;
  }

  const ScoredPoints& in_;
  std::vector<Eigen::Vector3f> points_, normals_;
  std::unique_ptr<PointIndex3> index_;
};

// An n-fold axis: each order dividing n with its own point (a box's centre, not a fitted
// circle's), coarse then fine; the largest order that agrees as well as the best one wins (a
// nearly square box's quarter turns agree a little less than its half turn: 2-fold).
SymmetryHypothesis BestOrder(const ScoredPoints& in, const AxisSearch& search,
                             const SymmetryHypothesis& axis, int n) {
  constexpr double kOrderTolerance = 0.01;
  std::vector<SymmetryHypothesis> orders;
  for (int m = n; m >= 2; --m) {
    if (n % m != 0) continue;
    SymmetryHypothesis h = axis;
    h.order = m;
    h.copies = m - 1;
    h.point = search.Search(axis.point, m, 10, 0.02f);
    h.point = search.Search(h.point, m, 4, 0.005f);
    in.Score(&h);
    orders.push_back(std::move(h));
  }
  double top = 0;
  for (const SymmetryHypothesis& h : orders) top = std::max(top, h.agreement);
  for (const SymmetryHypothesis& h : orders) {
    if (h.agreement >= top - kOrderTolerance) return h;
  }
  return axis;
}

// The best vertical axis: the circle fit's centre (over every observed point), moved by a local
// search (+- 6 % of the radius, 1 % steps), refined by the alignment cost, then its order.
SymmetryHypothesis BestAxis(const ScoredPoints& in,
                            const std::vector<Eigen::Vector3f>& all_points) {
  const AxisSearch search(in);
  SymmetryHypothesis axis;
  axis.kind = SymmetryKind::kAxis;
  axis.direction = in.frame.up;
  axis.point = search.Search(FitAxisPoint(all_points, in.frame), 0, 6, 0.01f);
  axis.copies = std::max(1, in.options.axis_steps - 1);
  in.Score(&axis);
  if (in.options.refine_axis) {
    SymmetryHypothesis refined = axis;
    refined.point = search.Refine(search.Refine(axis.point, 6, 0.01f), 4, 0.0025f);
    in.Score(&refined);
    if (refined.accepted || !axis.accepted) axis = refined;
  }
  if (const int n = DiscreteOrder(axis, in.options); n > 0) axis = BestOrder(in, search, axis, n);
  return axis;
}

}  // namespace

std::vector<SymmetryHypothesis> DetectSymmetries(const std::vector<Eigen::Vector3f>& all_points,
                                                 const std::vector<Eigen::Vector3f>& all_normals,
                                                 const ObjectFrame& frame,
                                                 const FreeSpaceGrid& free_space,
                                                 const SymmetryOptions& options,
                                                 const ObservedSurface* observed_surface) {
  std::vector<Eigen::Vector3f> points, normals;
  const size_t stride =
      std::max<size_t>(1, all_points.size() / static_cast<size_t>(std::max(1, options.max_points)));
  for (size_t i = 0; i < all_points.size(); i += stride) {
    points.push_back(all_points[i]);
    normals.push_back(all_normals[i]);
  }
  if (points.size() < 10) return {};
  const PointIndex3 index(points);
  const ScoredPoints in{points,
                        normals,
                        index,
                        frame,
                        free_space,
                        options,
                        options.cost_observed_surface ? observed_surface : nullptr};
  std::vector<SymmetryHypothesis> out = {BestAxis(in, all_points), BestPlane(in)};
  std::stable_sort(out.begin(), out.end(), Better);
  return out;
}

}  // namespace instascene::generation
