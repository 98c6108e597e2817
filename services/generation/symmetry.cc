// Symmetry hypotheses (symmetry.h) and how one is scored against the observed points; the search
// over them is in symmetry_search.cc.
#include "services/generation/symmetry.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "common/geometry/point_index.h"
#include "services/generation/symmetry_scoring.h"

namespace instascene::generation {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Distance of p from the plane / axis: points closer than the match distance map onto themselves.
float DistanceToElement(const SymmetryHypothesis& h, const Eigen::Vector3f& p) {
  const Eigen::Vector3f offset = p - h.point;
  if (h.kind == SymmetryKind::kPlane) return std::abs(offset.dot(h.direction));
  return (offset - offset.dot(h.direction) * h.direction).norm();
}

}  // namespace

Eigen::Matrix3f SymmetryHypothesis::Linear(int k) const {
  if (kind == SymmetryKind::kPlane) {
    return Eigen::Matrix3f::Identity() - 2.0f * direction * direction.transpose();
  }
  const double angle = 2.0 * kPi * (k + 1) / (copies + 1);
  return Eigen::AngleAxisf(static_cast<float>(angle), direction).toRotationMatrix();
}

Eigen::Vector3f SymmetryHypothesis::MapPoint(const Eigen::Vector3f& p, int k) const {
  return point + Linear(k) * (p - point);
}

std::string SymmetryHypothesis::Describe() const {
  std::string out = absl::StrFormat(
      "%s through (%.4f, %.4f, %.4f) %s (%.4f, %.4f, %.4f): agreement %.3f, "
      "evidence %.3f, %s",
      kind == SymmetryKind::kPlane ? "plane"
      : order > 0                  ? absl::StrFormat("%d-fold axis", order)
                                   : std::string("axis"),
      point.x(), point.y(), point.z(), kind == SymmetryKind::kPlane ? "normal" : "direction",
      direction.x(), direction.y(), direction.z(), agreement, evidence,
      accepted ? "accepted" : "rejected");
  if (kind == SymmetryKind::kAxis && copies > 1) {
    // Each turn's own agreement: where a revolution fails (a mug's handle) shows here.
    std::string turns;
    for (size_t k = 0; k < copy_agree.size() && k < copy_contradict.size(); ++k) {
      const int decided = copy_agree[k] + copy_contradict[k];
      absl::StrAppendFormat(&turns, "%s%.2f", k ? "/" : "",
                            decided ? static_cast<double>(copy_agree[k]) / decided : 0.0);
    }
    out += absl::StrCat("; turns ", turns);
  }
  return out;
}

namespace {

// The k-th image of observed point i under h: agreeing when an observed point with a compatible
// normal lies within `match` (its squared distance written to *dist_sq), contradicting when it
// lands in seen-empty space, unknown otherwise.
enum class Image { kAgrees, kContradicts, kUnknown };
Image ClassifyImage(const std::vector<Eigen::Vector3f>& points,
                    const std::vector<Eigen::Vector3f>& normals, const PointIndex3& index,
                    const FreeSpaceGrid& free_space, const SymmetryOptions& options, float match,
                    const SymmetryHypothesis& h, size_t i, int k, float* dist_sq) {
  const Eigen::Vector3f image = h.MapPoint(points[i], k);
  const auto [nearest, squared] = index.Nearest(image);
  *dist_sq = squared;
  if (squared <= match * match &&
      std::abs((h.Linear(k) * normals[i]).dot(normals[nearest])) >= options.normal_agreement) {
    return Image::kAgrees;
  }
  return free_space.IsFree(image) ? Image::kContradicts : Image::kUnknown;
}

}  // namespace

namespace symmetry_internal {

// Vertical axis through the least-squares common centre of the horizontal circles the points lie
// on (Kasa fit with one radius per height bin): the axis of a solid of revolution.
Eigen::Vector3f FitAxisPoint(const std::vector<Eigen::Vector3f>& points, const ObjectFrame& frame) {
  const Eigen::Matrix3f basis = frame.Basis();
  constexpr int kBins = 16;
  struct Bin {
    double n = 0, x = 0, y = 0, r2 = 0;
  };
  std::vector<Bin> bins(kBins);
  std::vector<Eigen::Vector3d> local;
  std::vector<int> bin_of;
  for (const Eigen::Vector3f& p : points) {
    const Eigen::Vector3d q = (basis.transpose() * (p - frame.center)).cast<double>();
    const int b =
        std::clamp(static_cast<int>((q.z() / frame.radius + 1.0) * 0.5 * kBins), 0, kBins - 1);
    local.push_back(q);
    bin_of.push_back(b);
    bins[b].n += 1;
    bins[b].x += q.x();
    bins[b].y += q.y();
    bins[b].r2 += q.x() * q.x() + q.y() * q.y();
  }
  // Minimise sum ((r2 - mean r2) - 2a (x - mean x) - 2b (y - mean y))^2 over (a, b).
  Eigen::Matrix2d ata = Eigen::Matrix2d::Zero();
  Eigen::Vector2d atb = Eigen::Vector2d::Zero();
  for (size_t i = 0; i < local.size(); ++i) {
    const Bin& bin = bins[bin_of[i]];
    const Eigen::Vector2d a(2 * (local[i].x() - bin.x / bin.n), 2 * (local[i].y() - bin.y / bin.n));
    const double r = local[i].x() * local[i].x() + local[i].y() * local[i].y() - bin.r2 / bin.n;
    ata += a * a.transpose();
    atb += a * r;
  }
  Eigen::Vector2d ab = Eigen::Vector2d::Zero();
  if (std::abs(ata.determinant()) > 1e-18) ab = ata.ldlt().solve(atb);
  // Keep the axis inside the object's extent (a degenerate fit must not leave it).
  if (ab.norm() > frame.radius) ab *= frame.radius / ab.norm();
  return frame.center + basis.col(0) * static_cast<float>(ab.x()) +
         basis.col(1) * static_cast<float>(ab.y());
}

bool Better(const SymmetryHypothesis& a, const SymmetryHypothesis& b) {
  if (a.accepted != b.accepted) return a.accepted;
  const double sa = a.agreement * std::min(1.0, a.evidence * 2);
  const double sb = b.agreement * std::min(1.0, b.evidence * 2);
  return sa > sb;
}

// The vertical plane whose normal is at `theta` from the frame's first horizontal axis, `offset`
// along that normal from the frame's centre.
SymmetryHypothesis VerticalPlane(const ObjectFrame& frame, double theta, float offset) {
  const Eigen::Matrix3f basis = frame.Basis();
  SymmetryHypothesis h;
  h.kind = SymmetryKind::kPlane;
  h.copies = 1;
  h.direction = (basis.col(0) * static_cast<float>(std::cos(theta)) +
                 basis.col(1) * static_cast<float>(std::sin(theta)))
                    .normalized();
  h.point = frame.center + offset * h.direction;
  return h;
}

void ScoreWithIndex(const std::vector<Eigen::Vector3f>& points,
                    const std::vector<Eigen::Vector3f>& normals, const PointIndex3& index,
                    const ObjectFrame& frame, const FreeSpaceGrid& free_space,
                    const SymmetryOptions& options, SymmetryHypothesis* h) {
  const float match = options.match_spacings * std::max(frame.spacing, 1e-6f);
  h->scored = h->agree = h->contradict = 0;
  h->copy_agree.assign(h->copies, 0);
  h->copy_contradict.assign(h->copies, 0);
  for (size_t i = 0; i < points.size(); ++i) {
    if (DistanceToElement(*h, points[i]) < match) continue;
    ++h->scored;
    for (int k = 0; k < h->copies; ++k) {
      float dist_sq = 0;
      switch (
          ClassifyImage(points, normals, index, free_space, options, match, *h, i, k, &dist_sq)) {
        case Image::kAgrees:
          ++h->agree;
          ++h->copy_agree[k];
          break;
        case Image::kContradicts:
          ++h->contradict;
          ++h->copy_contradict[k];
          break;
        case Image::kUnknown:
          break;
      }
    }
  }
  const int decided = h->agree + h->contradict;
  h->agreement = decided > 0 ? static_cast<double>(h->agree) / decided : 0.0;
  h->evidence = h->scored > 0 ? static_cast<double>(decided) / (h->scored * h->copies) : 0.0;
  const double needed = h->kind == SymmetryKind::kPlane
                            ? std::max(options.min_agreement, options.min_plane_agreement)
                            : options.min_agreement;
  h->accepted = h->agreement >= needed && h->evidence >= options.min_evidence;
  if (options.revolution_every_turn && h->accepted && h->order == 0 &&
      h->kind == SymmetryKind::kAxis) {
    h->accepted = AgreesAtEveryTurn(*h, options);
  }
}

// How far a hypothesis maps the observed points from observed points, over the images it decides
// (as ScoreWithIndex: agreeing or in seen-empty space; images in unseen space do not count, or the
// cost would favour planes that bisect whatever part was seen): an agreeing image costs its
// squared distance to the nearest observed point, a contradicting one the squared match distance;
// normalised by match^2 and the decided images. Agreement counts images within the match distance
// and is flat across a few degrees; this cost is not, so it places a plane to a fraction of a step.
// An image beyond the match distance from every observed surfel that stands in front of a seen
// one (ObservedSurface::InFrontOfSeenSurface) counts as contradicting: the free-space grid stops
// its rays a margin before the first surface, and an image there would otherwise leave the cost.
// (Nearer images with a turned normal stay unknown: asked too, they moved 13 planes of 45 scenes
// by more than 0.3 mm, 9 of them away from their objects' centres.)
double AlignmentCost(const std::vector<Eigen::Vector3f>& points,
                     const std::vector<Eigen::Vector3f>& normals, const PointIndex3& index,
                     const ObjectFrame& frame, const FreeSpaceGrid& free_space,
                     const SymmetryOptions& options, const SymmetryHypothesis& h,
                     const ObservedSurface* surface) {
  const float match = options.match_spacings * std::max(frame.spacing, 1e-6f);
  double cost = 0;
  size_t decided = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    for (int k = 0; k < h.copies; ++k) {
      float dist_sq = 0;
      Image image =
          ClassifyImage(points, normals, index, free_space, options, match, h, i, k, &dist_sq);
      if (image == Image::kUnknown && surface != nullptr && dist_sq > match * match &&
          surface->InFrontOfSeenSurface(h.MapPoint(points[i], k))) {
        image = Image::kContradicts;
      }
      if (image == Image::kUnknown) continue;
      cost += image == Image::kAgrees ? dist_sq : match * match;
      ++decided;
    }
  }
  return decided ? cost / (decided * static_cast<double>(match) * match) : 1.0;
}

}  // namespace symmetry_internal

int DiscreteOrder(const SymmetryHypothesis& h, const SymmetryOptions& options) {
  constexpr double kTurnSpread = 0.1;
  const int steps = h.copies + 1;
  auto turn_agreement = [&](int k) {
    const int decided = h.copy_agree[k] + h.copy_contradict[k];
    return decided > 0 ? static_cast<double>(h.copy_agree[k]) / decided : 0.0;
  };
  for (int n = steps / 2; n >= 2; --n) {
    if (steps % n != 0) continue;
    int group_decided = 0, rest_agree = 0, rest_decided = 0;
    double worst = 1, best = 0, rest_best = 0;
    for (int k = 0; k < h.copies; ++k) {
      const int decided = h.copy_agree[k] + h.copy_contradict[k];
      if ((k + 1) % (steps / n) == 0) {
        group_decided += decided;
        worst = std::min(worst, turn_agreement(k));
        best = std::max(best, turn_agreement(k));
      } else {
        rest_agree += h.copy_agree[k];
        rest_decided += decided;
        if (decided >= options.min_turn_decided) rest_best = std::max(rest_best, turn_agreement(k));
      }
    }
    if (group_decided == 0 || rest_decided == 0) continue;
    const bool group_holds = worst >= options.min_agreement && worst >= best - kTurnSpread &&
                             group_decided >= options.min_evidence * h.scored * (n - 1);
    if (group_holds && rest_agree < options.min_agreement * rest_decided &&
        (!options.order_outagrees_other_turns || rest_best < worst)) {
      return n;
    }
  }
  return 0;
}

bool AgreesAtEveryTurn(const SymmetryHypothesis& h, const SymmetryOptions& options) {
  // The one-sided 95 % Wilson score upper bound of agree / decided.
  auto upper_bound = [](int agree, int decided) {
    constexpr double z = 1.6449;
    const double p = static_cast<double>(agree) / decided, z2n = z * z / decided;
    const double spread = z * std::sqrt(p * (1 - p) / decided + z2n / (4.0 * decided));
    return (p + z2n / 2 + spread) / (1 + z2n);
  };
  for (size_t k = 0; k < h.copy_agree.size() && k < h.copy_contradict.size(); ++k) {
    const int decided = h.copy_agree[k] + h.copy_contradict[k];
    if (decided >= options.min_turn_decided &&
        upper_bound(h.copy_agree[k], decided) < options.min_agreement) {
      return false;
    }
  }
  return true;
}

void ScoreHypothesis(const std::vector<Eigen::Vector3f>& points,
                     const std::vector<Eigen::Vector3f>& normals, const ObjectFrame& frame,
                     const FreeSpaceGrid& free_space, const SymmetryOptions& options,
                     SymmetryHypothesis* h) {
  const PointIndex3 index(points);
  symmetry_internal::ScoreWithIndex(points, normals, index, frame, free_space, options, h);
}

}  // namespace instascene::generation
