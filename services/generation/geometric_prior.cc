#include "services/generation/geometric_prior.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <unordered_map>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/geometry/point_index.h"
#include "common/geometry/rigid.h"
#include "common/mesh/ray_caster.h"
#include "common/mesh/surfel_mesh.h"
#include "services/generation/observed_surface.h"

namespace instascene::generation {
namespace {

Eigen::Matrix3f SurfelRotation(const GaussianCloud& cloud, size_t g) {
  const float* q = &cloud.rotations[4 * g];
  return RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]).cast<float>();
}

// Positions already holding a surfel, hashed on a grid of the cover distance: the "already
// covered" test for surfels added so far (observed ones use a k-d tree).
class CoverSet {
 public:
  explicit CoverSet(float radius) : radius_(radius) {}
  bool Covered(const Eigen::Vector3f& p) const {
    const Eigen::Vector3i c = Cell(p);
    for (int dz = -1; dz <= 1; ++dz) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const auto it = cells_.find(Key(c + Eigen::Vector3i(dx, dy, dz)));
          if (it == cells_.end()) continue;
          for (const Eigen::Vector3f& q : it->second) {
            if ((q - p).squaredNorm() <= radius_ * radius_) return true;
          }
        }
      }
    }
    return false;
  }
  void Add(const Eigen::Vector3f& p) { cells_[Key(Cell(p))].push_back(p); }

 private:
  Eigen::Vector3i Cell(const Eigen::Vector3f& p) const {
    return (p / radius_).array().floor().cast<int>();
  }
  static int64_t Key(const Eigen::Vector3i& c) {
    return ((static_cast<int64_t>(c.x()) & 0x1FFFFF) << 42) |
           ((static_cast<int64_t>(c.y()) & 0x1FFFFF) << 21) |
           (static_cast<int64_t>(c.z()) & 0x1FFFFF);
  }
  float radius_;
  std::unordered_map<int64_t, std::vector<Eigen::Vector3f>> cells_;
};

using Candidate = SurfelCandidate;

GaussianCloud BuildSurfels(const GaussianCloud& instance, const std::vector<Candidate>& added) {
  GaussianCloud out;
  out.num_scales = 2;
  out.sh_degree = instance.sh_degree;
  out.Resize(added.size());
  const int stride = instance.sh_stride();
  for (size_t i = 0; i < added.size(); ++i) {
    const Candidate& c = added[i];
    for (int k = 0; k < 3; ++k) out.positions[3 * i + k] = c.position[k];
    const Eigen::Vector4d q = QuaternionWxyzFromRotation(c.rotation.cast<double>());
    for (int k = 0; k < 4; ++k) out.rotations[4 * i + k] = static_cast<float>(q[k]);
    if (c.has_scale) {
      out.log_scales[2 * i] = c.log_scale_u;
      out.log_scales[2 * i + 1] = c.log_scale_v;
    } else {
      out.log_scales[2 * i] = instance.log_scales[instance.num_scales * c.source];
      out.log_scales[2 * i + 1] = instance.log_scales[instance.num_scales * c.source + 1];
    }
    out.opacity_logits[i] = instance.opacity_logits[c.source];
    // View-dependent SH terms would have to be mirrored / rotated with the surfel; completed
    // surfels keep the view-independent colour (DC) only.
    for (int k = 0; k < 3; ++k) out.sh[stride * i + k] = instance.sh[stride * c.source + k];
  }
  return out;
}

// The open lower end of a revolved surface (a sphere's unseen underside): a disc of candidates
// `step` apart across the lowest ring of an accepted axis, facing down the axis, appearance from
// the nearest ring surfel. Nothing when that ring is already (nearly) closed.
std::vector<Candidate> AxisCap(const SymmetryHypothesis& h, const ObjectFrame& frame,
                               const std::vector<Eigen::Vector3f>& positions,
                               const std::vector<uint32_t>& sources, float step) {
  const Eigen::Vector3f up = h.direction.dot(frame.up) >= 0 ? h.direction : -h.direction;
  float lowest = std::numeric_limits<float>::max();
  for (const Eigen::Vector3f& p : positions) lowest = std::min(lowest, up.dot(p - h.point));
  std::vector<size_t> band;
  std::vector<float> radii;
  for (size_t i = 0; i < positions.size(); ++i) {
    const Eigen::Vector3f rel = positions[i] - h.point;
    if (up.dot(rel) > lowest + step) continue;
    band.push_back(i);
    radii.push_back((rel - up.dot(rel) * up).norm());
  }
  std::vector<Candidate> out;
  if (radii.empty()) return out;
  std::nth_element(radii.begin(), radii.begin() + radii.size() / 2, radii.end());
  const float radius = radii[radii.size() / 2];
  if (radius < 2 * step) return out;
  const Eigen::Vector3f e1 = up.unitOrthogonal(), e2 = up.cross(e1);
  const Eigen::Vector3f centre = h.point + lowest * up;
  for (float rho = 0; rho < radius - 0.5f * step; rho += step) {
    const int n = rho == 0 ? 1 : std::max(1, static_cast<int>(std::round(2 * M_PI * rho / step)));
    for (int k = 0; k < n; ++k) {
      const float angle = 2 * static_cast<float>(M_PI) * k / n;
      Candidate c;
      c.position = centre + rho * (std::cos(angle) * e1 + std::sin(angle) * e2);
      c.rotation << e1, -e2, -up;  // normal down the axis
      float best = std::numeric_limits<float>::max();
      for (size_t i : band) {
        const float d = (positions[i] - c.position).squaredNorm();
        if (d < best) {
          best = d;
          c.source = sources[i];
        }
      }
      out.push_back(c);
    }
  }
  return out;
}

// Per surfel, the body's outer radius about an axis at the surfel's height: the 90th percentile
// (`percent`) of the radii of the `body` surfels over the heights around it (at least 2 `step`s
// either side, more until the window holds `min_count` of them, so that a few strays there stay
// above the percentile), plus one `step`. Infinite everywhere when the body holds fewer than
// `min_count`.
std::vector<float> RadialProfile(const std::vector<float>& height, const std::vector<float>& radial,
                                 const std::vector<uint8_t>& body, float step, int percent = 90,
                                 size_t min_count = 40) {
  std::vector<float> out(height.size(), std::numeric_limits<float>::infinity());
  if (static_cast<size_t>(std::count(body.begin(), body.end(), 1)) < min_count) return out;
  const float low = *std::min_element(height.begin(), height.end());
  const int bins =
      static_cast<int>((*std::max_element(height.begin(), height.end()) - low) / step) + 1;
  auto bin_of = [&](size_t g) {
    return std::clamp(static_cast<int>((height[g] - low) / step), 0, bins - 1);
  };
  std::vector<std::vector<float>> by_bin(bins);
  for (size_t g = 0; g < height.size(); ++g) {
    if (body[g]) by_bin[bin_of(g)].push_back(radial[g]);
  }
  std::vector<size_t> below(bins + 1, 0);  // body surfels in bins [0, i)
  for (int i = 0; i < bins; ++i) below[i + 1] = below[i] + by_bin[i].size();
  std::vector<float> profile(bins), window;
  for (int i = 0; i < bins; ++i) {
    int half = 2;
    while (below[std::min(bins, i + half + 1)] - below[std::max(0, i - half)] < min_count) ++half;
    window.clear();
    for (int j = std::max(0, i - half); j <= std::min(bins - 1, i + half); ++j)
      window.insert(window.end(), by_bin[j].begin(), by_bin[j].end());
    const size_t q = window.size() * percent / 100;
    std::nth_element(window.begin(), window.begin() + q, window.end());
    profile[i] = window[q] + step;
  }
  for (size_t g = 0; g < height.size(); ++g) out[g] = profile[bin_of(g)];
  return out;
}

}  // namespace

absl::StatusOr<PriorOutput> NoPrior::Complete(const PriorInput& input) const {
  PriorOutput out;
  out.added.num_scales = 2;
  out.added.sh_degree = input.instance->sh_degree;
  out.abstained = true;
  out.reason = "prior 'none': the object is the closed crop";
  return out;
}

absl::StatusOr<PriorOutput> GeometricPrior::Complete(const PriorInput& input) const {
  RETURN_IF_ERROR(options_.observed_surface.Validate());
  const GaussianCloud& instance = *input.instance;
  const ObjectFrame& frame = input.frame;
  std::vector<Eigen::Vector3f> points(instance.size()), normals(instance.size());
  for (size_t g = 0; g < instance.size(); ++g) {
    points[g] = Eigen::Vector3f(&instance.positions[3 * g]);
    normals[g] = SurfelRotation(instance, g).col(2);
  }
  const std::vector<SymmetryHypothesis> hypotheses =
      DetectSymmetries(points, normals, frame, *input.free_space, options_.symmetry);
  RETURN_IF_ERROR(CheckCancelled(input.cancel, "complete"));
  const PointIndex3 observed(points);
  const ObservedSurface observed_surface(&observed, normals, input.seen_through, frame.center,
                                         frame.spacing, options_.observed_surface);
  const float cover = options_.cover_spacings * std::max(frame.spacing, 1e-6f);
  CoverSet added_set(cover);
  std::vector<Candidate> added;
  int rejected_free = 0, rejected_covered = 0, rejected_below = 0, rejected_open = 0,
      rejected_off_surface = 0;
  auto consider = [&](const Candidate& c) {
    if (frame.has_support &&
        frame.up.dot(c.position) < frame.support_height - 0.5f * frame.spacing) {
      ++rejected_below;
      return;
    }
    if (input.free_space->FreeViews(c.position) >= options_.candidate_free_views) {
      ++rejected_free;
      return;
    }
    if (observed.Nearest(c.position).second <= cover * cover || added_set.Covered(c.position)) {
      ++rejected_covered;
      return;
    }
    if (observed_surface.Contradicts(c.position)) {
      ++rejected_off_surface;
      return;
    }
    // The exact test last (a few rays per real view): the grid is coarse and its margin keeps
    // 1.5 voxels in front of every surface uncarved.
    if (options_.exact_free_space && input.seen_through != nullptr &&
        input.seen_through->SeenThrough(c.position)) {
      ++rejected_free;
      return;
    }
    added_set.Add(c.position);
    added.push_back(c);
  };
  nlohmann::json tried = nlohmann::json::array();
  int skipped_sources = 0, axis_skipped = 0, profile_skipped = 0, handle_joined = 0;
  std::vector<uint8_t> handle(instance.size(), 0);  // parts of the object an axis does not hold for
  int accepted = 0;
  std::map<std::string, int> added_by;
  // A part a hypothesis does not hold for (a mug's handle under the body's axis) has images in
  // seen-empty space: such a surfel lends that hypothesis no images at all.
  auto asymmetric_sources = [&](const SymmetryHypothesis& h) {
    std::vector<uint8_t> asymmetric(instance.size(), 0);
    for (uint32_t g = 0; g < instance.size(); ++g) {
      int contradicted = 0;
      for (int k = 0; k < h.copies; ++k) {
        const Eigen::Vector3f image = h.MapPoint(points[g], k);
        // The grid's voxels straddle a thin object's surface where views graze it: the exact
        // test tells seen-empty space from the surface at the surfel's own scale.
        contradicted += input.free_space->IsFree(image) &&
                        (!options_.exact_asymmetry || input.seen_through == nullptr ||
                         input.seen_through->ViewsSeeingThrough(image) > 0);
      }
      asymmetric[g] = contradicted > std::max(0, h.copies / 4);
    }
    return asymmetric;
  };
  // What each accepted revolution axis holds for, computed once per axis.
  constexpr double kMaxAxisAsymmetricShare = 0.3;
  struct AxisBody {
    const SymmetryHypothesis* axis = nullptr;
    std::vector<uint8_t> off;  // asymmetric_sources(*axis)
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
  // Per instance surfel: a touching neighbour's label surrounds it (null when not given).
  const std::vector<uint8_t>* neighbour_labelled =
      input.neighbour_labelled != nullptr && input.neighbour_labelled->size() == instance.size()
          ? input.neighbour_labelled
          : nullptr;
  auto neighbours = [&](uint32_t g) {
    return neighbour_labelled != nullptr && (*neighbour_labelled)[g] != 0;
  };
  std::vector<AxisBody> bodies;
  for (const SymmetryHypothesis& axis : hypotheses) {
    if (!axis.accepted || axis.kind != SymmetryKind::kAxis) continue;
    AxisBody b;
    b.axis = &axis;
    b.off_beyond_body.assign(instance.size(), 0);
    b.beyond_profile.assign(instance.size(), 0);
    b.off = asymmetric_sources(axis);
    const std::vector<uint8_t>& off = b.off;
    std::vector<float> radial(instance.size()), height(instance.size()), body;
    for (uint32_t g = 0; g < instance.size(); ++g) {
      const Eigen::Vector3f d = points[g] - axis.point;
      height[g] = d.dot(axis.direction);
      radial[g] = (d - height[g] * axis.direction).norm();
      if (!off[g]) body.push_back(radial[g]);
    }
    // An axis that most of the object contradicts (a tilted or offset fit) tells no handle from
    // its own error.
    if (body.empty() || body.size() < (1.0 - kMaxAxisAsymmetricShare) * off.size()) continue;
    // Only what sticks out beyond the body the axis holds for (a handle, not the body's own
    // surfels that a slightly offset axis revolves into seen-empty space).
    const size_t q = body.size() * 95 / 100;
    std::nth_element(body.begin(), body.begin() + q, body.end());
    const float step = std::max(frame.spacing, 1e-6f);
    const float reach = body[std::min(q, body.size() - 1)] + step;
    for (uint32_t g = 0; g < instance.size(); ++g)
      b.off_beyond_body[g] = off[g] && radial[g] > reach;
    // About a solid of revolution only (an n-fold axis's radius varies around it: a box's
    // corners stand clear of its median radius).
    if (options_.handle_joins_its_part && axis.order == 0 &&
        std::find(b.off_beyond_body.begin(), b.off_beyond_body.end(), 1) !=
            b.off_beyond_body.end()) {
      // Clear of the body: more than 3 spacings beyond its median radius at the surfel's height
      // (the 95th percentile above, and the profile's 90th, stand on the handle's lower end
      // where it is a tenth of the surfels).
      std::vector<uint8_t> held(instance.size());
      for (uint32_t g = 0; g < instance.size(); ++g) held[g] = !off[g];
      const std::vector<float> median = RadialProfile(height, radial, held, step, 50);
      // Per part (a component grown from the sources the axis does not hold for), within 3
      // spacings, repeatedly. A part that reaches a surfel a neighbour's label surrounds is that
      // neighbour's patch at the contact, not a handle: the rules below judge it.
      const float link = 3.0f * step;
      std::vector<uint8_t> seen(instance.size(), 0);
      std::vector<uint32_t> part, queue;
      for (uint32_t seed = 0; seed < instance.size(); ++seed) {
        if (!b.off_beyond_body[seed] || seen[seed] || neighbours(seed)) continue;
        part.assign(1, seed);
        queue.assign(1, seed);
        seen[seed] = 1;
        bool touches = false;
        while (!queue.empty()) {
          const uint32_t g = queue.back();
          queue.pop_back();
          for (uint32_t n : observed.WithinRadius(points[g], link)) {
            touches |= neighbours(n);
            if (seen[n] || neighbours(n) || radial[n] <= median[n] + 2.0f * step) continue;
            seen[n] = 1;  // each surfel enters one part once
            part.push_back(n);
            queue.push_back(n);
          }
        }
        if (touches) continue;
        for (uint32_t g : part) {
          handle_joined += !b.off[g];
          b.off[g] = 1;
          b.off_beyond_body[g] = 1;
          handle[g] = 1;
        }
      }
    }
    // Beyond the profile: only about a solid of revolution (an n-fold axis's radius varies
    // around it: a box's corners).
    if (options_.skip_beyond_axis_profile && axis.order == 0) {
      // The profile is the body's: a surfel a touching neighbour's label surrounds is a suspect
      // it is to judge, not a witness (a neighbour's surfels crowding one height can be a tenth
      // of the window and lift the percentile over themselves).
      std::vector<uint8_t> holds(instance.size());
      for (uint32_t g = 0; g < instance.size(); ++g)
        holds[g] = !off[g] && !(options_.profile_skips_neighbour_labelled && neighbours(g));
      std::vector<float> profile = RadialProfile(height, radial, holds, step);
      for (uint32_t g = 0; g < instance.size(); ++g)
        if (neighbours(g)) profile[g] -= (1.0f - options_.neighbour_profile_spacings) * step;
      for (uint32_t g = 0; g < instance.size(); ++g)
        b.beyond_profile[g] = !off[g] && radial[g] > profile[g];
      if (options_.drop_neighbours_beyond_axis_profile && neighbour_labelled != nullptr) {
        b.neighbours_beyond_profile.assign(instance.size(), 0);
        b.off_beyond_profile.assign(instance.size(), 0);
        for (uint32_t g = 0; g < instance.size(); ++g) {
          b.off_beyond_profile[g] = off[g] && radial[g] > profile[g];
          b.neighbours_beyond_profile[g] = b.off_beyond_profile[g] && neighbours(g);
        }
      }
    }
    // About an n-fold axis (no profile: a box's radius varies around it), those beyond the body's
    // reach (its corners) that the axis does not hold for and a neighbour's label surrounds.
    if (axis.order != 0 && options_.drop_neighbours_beyond_axis_profile &&
        neighbour_labelled != nullptr) {
      b.neighbours_beyond_profile.assign(instance.size(), 0);
      for (uint32_t g = 0; g < instance.size(); ++g)
        b.neighbours_beyond_profile[g] = b.off_beyond_body[g] && neighbours(g);
    }
    bodies.push_back(std::move(b));
  }
  std::vector<uint8_t> foreign(instance.size(), 0);
  std::vector<uint32_t> own;  // the instance surfels that are the object's
  for (uint32_t g = 0; g < instance.size(); ++g) {
    for (const AxisBody& b : bodies) {
      foreign[g] |= options_.drop_beyond_axis_profile && b.beyond_profile[g];
      foreign[g] |= !b.neighbours_beyond_profile.empty() && b.neighbours_beyond_profile[g];
    }
  }
  // A neighbour's patch at the contact: surfels beyond the profile that the axis does not hold
  // for and that join a surfel found not to be the object's (within three spacings, repeatedly)
  // are not the object's either. They are the patch's inner part, too far from every other
  // instance's surfel for the neighbour-label test (its rim passes it).
  if (options_.drop_patches_beyond_axis_profile) {
    std::vector<uint8_t> candidate(instance.size(), 0);
    bool any = false;
    for (const AxisBody& b : bodies) {
      if (b.off_beyond_profile.empty()) continue;
      for (uint32_t g = 0; g < instance.size(); ++g) {
        candidate[g] |= b.off_beyond_profile[g] && !foreign[g] && !handle[g];
        any |= candidate[g] != 0;
      }
    }
    if (any) {
      const PointIndex3 index(points);  // a copy: the index keeps its own
      std::vector<uint32_t> queue;
      for (uint32_t g = 0; g < instance.size(); ++g)
        if (foreign[g]) queue.push_back(g);
      const float link = 3.0f * std::max(frame.spacing, 1e-6f);
      while (!queue.empty()) {
        const uint32_t g = queue.back();
        queue.pop_back();
        for (uint32_t n : index.WithinRadius(points[g], link)) {
          if (!candidate[n] || foreign[n]) continue;
          foreign[n] = 1;
          queue.push_back(n);
        }
      }
    }
  }
  for (uint32_t g = 0; g < instance.size(); ++g) {
    if (!foreign[g]) own.push_back(g);
  }
  // Sources a hypothesis lends no images of beyond its own asymmetric ones: an axis, those beyond
  // its profile; a plane containing an axis (oriented about it only by the parts the axis does
  // not hold for), those and the parts beyond the body that the axis does not hold for.
  auto skipped_for = [&](const SymmetryHypothesis& h) {
    std::vector<uint8_t> skip(instance.size(), 0);
    const float sin_tolerance = std::sin(10.0f * static_cast<float>(M_PI) / 180.0f);
    for (const AxisBody& b : bodies) {
      const SymmetryHypothesis& axis = *b.axis;
      if (&h == &axis) {
        for (uint32_t g = 0; g < skip.size(); ++g) skip[g] |= b.beyond_profile[g];
        continue;
      }
      if (h.kind != SymmetryKind::kPlane || !options_.mirror_skips_axis_asymmetric) continue;
      if (std::abs(axis.direction.dot(h.direction)) > sin_tolerance ||
          std::abs(h.direction.dot(axis.point - h.point)) > 2.0f * frame.spacing) {
        continue;  // the plane does not contain this axis
      }
      for (uint32_t g = 0; g < skip.size(); ++g)
        skip[g] |= b.off_beyond_body[g] | b.beyond_profile[g];
    }
    return skip;
  };
  for (const SymmetryHypothesis& h : hypotheses) {
    tried.push_back(h.Describe());
    if (!h.accepted) continue;
    ++accepted;
    const size_t before = added.size();
    auto body =
        std::find_if(bodies.begin(), bodies.end(), [&](const AxisBody& b) { return b.axis == &h; });
    std::vector<uint8_t> asymmetric = body != bodies.end() ? body->off : asymmetric_sources(h);
    const std::vector<uint8_t> axis_skip = skipped_for(h);
    for (size_t g = 0; g < asymmetric.size(); ++g) {
      skipped_sources += asymmetric[g];
      (h.kind == SymmetryKind::kAxis ? profile_skipped : axis_skipped) +=
          axis_skip[g] && !asymmetric[g];
      asymmetric[g] |= axis_skip[g] | foreign[g];  // not the object's: no images by any hypothesis
    }
    for (int k = 0; k < h.copies; ++k) {
      const Eigen::Matrix3f linear = h.Linear(k);
      for (uint32_t g = 0; g < instance.size(); ++g) {
        if (asymmetric[g]) continue;
        const Eigen::Matrix3f r = SurfelRotation(instance, g);
        Candidate c;
        c.position = h.MapPoint(points[g], k);
        const Eigen::Vector3f u = linear * r.col(0), v = linear * r.col(1);
        c.rotation << u, v, u.cross(v);
        c.source = g;
        consider(c);
      }
      RETURN_IF_ERROR(CheckCancelled(input.cancel, "complete"));
    }
    added_by[h.kind == SymmetryKind::kPlane ? "mirrored" : "revolved"] +=
        static_cast<int>(added.size() - before);
  }
  // The lower end of each accepted axis, closed across its lowest ring.
  if (options_.axis_cap) {
    for (const SymmetryHypothesis& h : hypotheses) {
      // An n-fold axis (a box) has no round lower ring: the support cap closes its bottom.
      if (!h.accepted || h.kind != SymmetryKind::kAxis || h.order > 0) continue;
      std::vector<Eigen::Vector3f> positions;
      std::vector<uint32_t> sources = own;
      for (uint32_t g : own) positions.push_back(points[g]);
      for (const Candidate& c : added) {
        positions.push_back(c.position);
        sources.push_back(c.source);
      }
      const size_t before = added.size();
      // The cap closes an underside: straight up from each disc point the object's own surface
      // must lie within 2 radii. Where the column is open (a torus' hole, seen through from
      // above), the disc would close a hole instead.
      ASSIGN_OR_RETURN(std::unique_ptr<RayCaster> own_surface,
                       RayCaster::Create(SurfelDiscs(instance, {}, SurfelDiscOptions{})));
      const Eigen::Vector3f up = h.direction.dot(frame.up) >= 0 ? h.direction : -h.direction;
      for (const Candidate& c : AxisCap(h, frame, positions, sources, 1.01f * cover)) {
        if (!own_surface->Cast(c.position, up, 0.0f, 2.0f * frame.radius).hit) {
          ++rejected_open;
          continue;
        }
        consider(c);
      }
      added_by["axis_cap"] += static_cast<int>(added.size() - before);
    }
  }
  PriorOutput out;
  out.report["hypotheses"] = tried;
  if (accepted == 0) {
    out.abstained = true;
    out.reason = hypotheses.empty() ? "too few observed surfels to test any symmetry"
                                    : "no symmetry hypothesis passed";
    out.added = BuildSurfels(instance, {});
    out.report["added"] = 0;
    return out;
  }
  // The support: walls extended down to it, then the underside closed on it.
  if (options_.support_cap && frame.has_support &&
      frame.bottom_height - frame.support_height <= options_.max_support_gap_radii * frame.radius) {
    std::vector<Eigen::Vector3f> positions;
    std::vector<Eigen::Matrix3f> rotations;
    std::vector<uint32_t> sources;
    for (uint32_t g : own) {
      positions.push_back(points[g]);
      rotations.push_back(SurfelRotation(instance, g));
      sources.push_back(g);
    }
    auto gather = [&] {
      positions.resize(own.size());
      rotations.resize(own.size());
      sources.resize(own.size());
      for (const Candidate& c : added) {
        positions.push_back(c.position);
        rotations.push_back(c.rotation);
        sources.push_back(c.source);
      }
    };
    gather();
    size_t before = added.size();
    // A vertical axis of revolution: sloped walls follow the profile's curvature about it.
    std::optional<Eigen::Vector3f> vertical_axis;
    for (const SymmetryHypothesis& h : hypotheses) {
      if (options_.walls_follow_curvature && h.accepted && h.kind == SymmetryKind::kAxis &&
          h.order == 0 &&
          std::abs(h.direction.dot(frame.up)) > std::cos(5.0f * std::numbers::pi_v<float> / 180)) {
        vertical_axis = h.point;
        break;
      }
    }
    for (const Candidate& c : WallExtension(positions, rotations, sources, frame,
                                            options_.wall_slope_min_sin, vertical_axis)) {
      consider(c);
    }
    added_by["support_walls"] = static_cast<int>(added.size() - before);
    gather();
    before = added.size();
    for (const Candidate& c : SupportCap(positions, sources, frame, *input.free_space)) consider(c);
    added_by["support_cap"] = static_cast<int>(added.size() - before);
  }
  out.added = BuildSurfels(instance, added);
  out.reason =
      absl::StrCat(accepted, " symmetry hypothesis(es) accepted; ", added.size(), " surfels added");
  out.report["added"] = added.size();
  out.report["added_by"] = added_by;
  out.report["asymmetric_sources"] = skipped_sources;
  out.report["mirror_axis_asymmetric_sources"] = axis_skipped;
  out.report["beyond_axis_profile_sources"] = profile_skipped;
  out.report["handle_joined_sources"] = handle_joined;
  for (const SymmetryHypothesis& h : hypotheses) {
    out.revolution_axis |= h.accepted && h.kind == SymmetryKind::kAxis && h.order == 0;
  }
  for (uint32_t g = 0; g < instance.size(); ++g) {
    if (foreign[g]) out.foreign.push_back(g);
  }
  out.report["foreign_observed"] = out.foreign.size();
  out.report["rejected"] = {{"observed_free", rejected_free},
                            {"already_covered", rejected_covered},
                            {"below_support", rejected_below},
                            {"off_observed_surface", rejected_off_surface},
                            {"axis_cap_open_above", rejected_open}};
  return out;
}

}  // namespace instascene::generation
