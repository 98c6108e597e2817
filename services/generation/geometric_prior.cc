#include "services/generation/geometric_prior.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <optional>
#include <string>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/geometry/point_index.h"
#include "common/geometry/rigid.h"
#include "common/mesh/ray_caster.h"
#include "common/mesh/surfel_mesh.h"
#include "services/generation/axis_bodies.h"
#include "services/generation/candidate_filter.h"
#include "services/generation/observed_surface.h"

namespace instascene::generation {
namespace {

Eigen::Matrix3f SurfelRotation(const GaussianCloud& cloud, size_t g) {
  const float* q = &cloud.rotations[4 * g];
  return RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]).cast<float>();
}

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

// Sources the accepted hypotheses lent no images (the prior's report).
struct SourceCounts {
  int asymmetric = 0;              // their images lie in seen-empty space
  int mirror_axis_asymmetric = 0;  // a plane skipped what an axis it contains does not hold for
  int beyond_axis_profile = 0;     // an axis skipped those beyond its profile
};

// Proposes to `filter` the images, under every copy of the accepted hypothesis `h`, of the
// instance surfels that `h` holds for and that are the object's.
absl::Status AddImages(const SymmetryHypothesis& h, const GaussianCloud& instance,
                       const InstanceSurfels& s, const AxisBodies& bodies,
                       const std::vector<uint8_t>& foreign, const GeometricPriorOptions& options,
                       const CancelFlag* cancel, SourceCounts* counts, CandidateFilter* filter) {
  const auto body = std::find_if(bodies.bodies.begin(), bodies.bodies.end(),
                                 [&](const AxisBody& b) { return b.axis == &h; });
  std::vector<uint8_t> asymmetric =
      body != bodies.bodies.end() ? body->off : AsymmetricSources(h, s, options.exact_asymmetry);
  const std::vector<uint8_t> skip = SkippedSources(h, bodies, s, options);
  for (size_t g = 0; g < asymmetric.size(); ++g) {
    counts->asymmetric += asymmetric[g];
    (h.kind == SymmetryKind::kAxis ? counts->beyond_axis_profile
                                   : counts->mirror_axis_asymmetric) += skip[g] && !asymmetric[g];
    asymmetric[g] |= skip[g] | foreign[g];  // not the object's: no images by any hypothesis
  }
  for (int k = 0; k < h.copies; ++k) {
    const Eigen::Matrix3f linear = h.Linear(k);
    for (uint32_t g = 0; g < instance.size(); ++g) {
      if (asymmetric[g]) continue;
      const Eigen::Matrix3f r = SurfelRotation(instance, g);
      Candidate c;
      c.position = h.MapPoint(s.points[g], k);
      const Eigen::Vector3f u = linear * r.col(0), v = linear * r.col(1);
      c.rotation << u, v, u.cross(v);
      c.source = g;
      filter->Consider(c);
    }
    RETURN_IF_ERROR(CheckCancelled(cancel, "complete"));
  }
  return absl::OkStatus();
}

// The lower end of each accepted axis of revolution, closed across its lowest ring (an n-fold
// axis, a box's, has no round lower ring: the support cap closes its bottom). The cap closes an
// underside: straight up from each disc point the object's own surface must lie within 2 radii.
// Where the column is open (a torus' hole, seen through from above), the disc would close a hole
// instead.
absl::Status AddAxisCaps(const std::vector<SymmetryHypothesis>& hypotheses,
                         const GaussianCloud& instance, const InstanceSurfels& s,
                         const std::vector<uint32_t>& own, CandidateFilter* filter,
                         std::map<std::string, int>* added_by) {
  for (const SymmetryHypothesis& h : hypotheses) {
    if (!h.accepted || h.kind != SymmetryKind::kAxis || h.order > 0) continue;
    std::vector<Eigen::Vector3f> positions;
    positions.reserve(own.size() + filter->added().size());
    std::vector<uint32_t> sources = own;
    for (uint32_t g : own) positions.push_back(s.points[g]);
    for (const Candidate& c : filter->added()) {
      positions.push_back(c.position);
      sources.push_back(c.source);
    }
    const size_t before = filter->added().size();
    ASSIGN_OR_RETURN(std::unique_ptr<RayCaster> own_surface,
                     RayCaster::Create(SurfelDiscs(instance, {}, SurfelDiscOptions{})));
    const Eigen::Vector3f up = h.direction.dot(s.frame.up) >= 0 ? h.direction : -h.direction;
    for (const Candidate& c : AxisCap(h, s.frame, positions, sources, 1.01f * filter->cover())) {
      if (!own_surface->Cast(c.position, up, 0.0f, 2.0f * s.frame.radius).hit) {
        ++filter->rejected().axis_cap_open_above;
        continue;
      }
      filter->Consider(c);
    }
    (*added_by)["axis_cap"] += static_cast<int>(filter->added().size() - before);
  }
  return absl::OkStatus();
}

// The support: walls extended down to it, then the underside closed on it.
void AddSupport(const std::vector<SymmetryHypothesis>& hypotheses, const GaussianCloud& instance,
                const InstanceSurfels& s, const std::vector<uint32_t>& own,
                const GeometricPriorOptions& options, CandidateFilter* filter,
                std::map<std::string, int>* added_by) {
  const ObjectFrame& frame = s.frame;
  std::vector<Eigen::Vector3f> positions;
  std::vector<Eigen::Matrix3f> rotations;
  std::vector<uint32_t> sources;
  for (uint32_t g : own) {
    positions.push_back(s.points[g]);
    rotations.push_back(SurfelRotation(instance, g));
    sources.push_back(g);
  }
  auto gather = [&] {
    positions.resize(own.size());
    rotations.resize(own.size());
    sources.resize(own.size());
    for (const Candidate& c : filter->added()) {
      positions.push_back(c.position);
      rotations.push_back(c.rotation);
      sources.push_back(c.source);
    }
  };
  gather();
  size_t before = filter->added().size();
  // A vertical axis of revolution: sloped walls follow the profile's curvature about it.
  std::optional<Eigen::Vector3f> vertical_axis;
  for (const SymmetryHypothesis& h : hypotheses) {
    if (options.walls_follow_curvature && h.accepted && h.kind == SymmetryKind::kAxis &&
        h.order == 0 &&
        std::abs(h.direction.dot(frame.up)) > std::cos(5.0f * std::numbers::pi_v<float> / 180)) {
      vertical_axis = h.point;
      break;
    }
  }
  for (const Candidate& c : WallExtension(positions, rotations, sources, frame,
                                          options.wall_slope_min_sin, vertical_axis)) {
    filter->Consider(c);
  }
  (*added_by)["support_walls"] = static_cast<int>(filter->added().size() - before);
  gather();
  before = filter->added().size();
  for (const Candidate& c :
       SupportCap(positions, sources, frame, s.free_space, options.cap_rim_inside_walls)) {
    filter->Consider(c);
  }
  (*added_by)["support_cap"] = static_cast<int>(filter->added().size() - before);
}

// The instance's surfel centres and normals.
void CentresAndNormals(const GaussianCloud& instance, std::vector<Eigen::Vector3f>* points,
                       std::vector<Eigen::Vector3f>* normals) {
  points->resize(instance.size());
  normals->resize(instance.size());
  for (size_t g = 0; g < instance.size(); ++g) {
    (*points)[g] = Eigen::Vector3f(&instance.positions[3 * g]);
    (*normals)[g] = SurfelRotation(instance, g).col(2);
  }
}

// The prior's output where hypotheses were accepted: the added surfels, the foreign observed
// ones, which axes the object has, and the report (what each hypothesis and cap added, the
// sources left out and the candidates rejected, by reason).
void FillOutput(const std::vector<SymmetryHypothesis>& hypotheses, const GaussianCloud& instance,
                const CandidateFilter& filter, const SourceCounts& counts, const AxisBodies& bodies,
                const std::vector<uint8_t>& foreign, int accepted,
                const std::map<std::string, int>& added_by, PriorOutput* out) {
  const std::vector<Candidate>& added = filter.added();
  out->added = BuildSurfels(instance, added);
  out->reason = accepted > 0 ? absl::StrCat(accepted, " symmetry hypothesis(es) accepted; ",
                                            added.size(), " surfels added")
                             : absl::StrCat("no symmetry hypothesis passed; ", added.size(),
                                            " surfels added on the support");
  out->report["added"] = added.size();
  out->report["added_by"] = added_by;
  out->report["asymmetric_sources"] = counts.asymmetric;
  out->report["mirror_axis_asymmetric_sources"] = counts.mirror_axis_asymmetric;
  out->report["beyond_axis_profile_sources"] = counts.beyond_axis_profile;
  out->report["handle_joined_sources"] = bodies.handle_joined;
  for (const SymmetryHypothesis& h : hypotheses) {
    out->revolution_axis |= h.accepted && h.kind == SymmetryKind::kAxis && h.order == 0;
    out->order_axis |= h.accepted && h.kind == SymmetryKind::kAxis && h.order > 0;
  }
  for (uint32_t g = 0; g < instance.size(); ++g) {
    if (foreign[g]) out->foreign.push_back(g);
  }
  out->report["foreign_observed"] = out->foreign.size();
  const CandidateRejections& rejected = filter.rejected();
  out->report["rejected"] = {{"observed_free", rejected.observed_free},
                             {"already_covered", rejected.already_covered},
                             {"below_support", rejected.below_support},
                             {"off_observed_surface", rejected.off_observed_surface},
                             {"axis_cap_open_above", rejected.axis_cap_open_above}};
}

// The hypotheses tried (described), how many were accepted, and what the accepted ones added.
struct ImagesAdded {
  nlohmann::json tried = nlohmann::json::array();
  int accepted = 0;
  SourceCounts counts;
  std::map<std::string, int> added_by;  // "mirrored" / "revolved" -> surfels
};

// Every accepted hypothesis's images of the instance's surfels, offered to the filter.
absl::StatusOr<ImagesAdded> AddAcceptedImages(const std::vector<SymmetryHypothesis>& hypotheses,
                                              const GaussianCloud& instance,
                                              const InstanceSurfels& s, const AxisBodies& bodies,
                                              const std::vector<uint8_t>& foreign,
                                              const GeometricPriorOptions& options,
                                              const CancelFlag* cancel, CandidateFilter* filter) {
  ImagesAdded images;
  for (const SymmetryHypothesis& h : hypotheses) {
    images.tried.push_back(h.Describe());
    if (!h.accepted) continue;
    ++images.accepted;
    const size_t before = filter->added().size();
    RETURN_IF_ERROR(
        AddImages(h, instance, s, bodies, foreign, options, cancel, &images.counts, filter));
    images.added_by[h.kind == SymmetryKind::kPlane ? "mirrored" : "revolved"] +=
        static_cast<int>(filter->added().size() - before);
  }
  return images;
}

// No hypothesis accepted: the object is its observed surfels.
PriorOutput Abstention(const std::vector<SymmetryHypothesis>& hypotheses,
                       const GaussianCloud& instance, PriorOutput out) {
  out.abstained = true;
  out.reason = hypotheses.empty() ? "too few observed surfels to test any symmetry"
                                  : "no symmetry hypothesis passed";
  out.added = BuildSurfels(instance, {});
  out.report["added"] = 0;
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
  std::vector<Eigen::Vector3f> points, normals;
  CentresAndNormals(instance, &points, &normals);
  const PointIndex3 observed(points);
  const ObservedSurface observed_surface(&observed, normals, input.seen_through, frame.center,
                                         frame.spacing, options_.observed_surface);
  const std::vector<SymmetryHypothesis> hypotheses = DetectSymmetries(
      points, normals, frame, *input.free_space, options_.symmetry, &observed_surface);
  RETURN_IF_ERROR(CheckCancelled(input.cancel, "complete"));
  CandidateFilter filter(frame, observed, observed_surface, *input.free_space, input.seen_through,
                         options_);
  const InstanceSurfels s{
      points,
      observed,
      frame,
      *input.free_space,
      input.seen_through,
      input.neighbour_labelled != nullptr && input.neighbour_labelled->size() == instance.size()
          ? input.neighbour_labelled
          : nullptr};
  // What the accepted axes hold for, and the instance surfels that are a neighbour's.
  const AxisBodies bodies = AnalyseAxisBodies(hypotheses, s, options_);
  const std::vector<uint8_t> foreign = ForeignSurfels(bodies, s, options_);
  std::vector<uint32_t> own;  // the instance surfels that are the object's
  for (uint32_t g = 0; g < instance.size(); ++g) {
    if (!foreign[g]) own.push_back(g);
  }
  ASSIGN_OR_RETURN(ImagesAdded images, AddAcceptedImages(hypotheses, instance, s, bodies, foreign,
                                                         options_, input.cancel, &filter));
  std::map<std::string, int>& added_by = images.added_by;
  if (options_.axis_cap) {
    RETURN_IF_ERROR(AddAxisCaps(hypotheses, instance, s, own, &filter, &added_by));
  }
  PriorOutput out;
  out.report["hypotheses"] = images.tried;
  if ((images.accepted > 0 || options_.support_without_symmetry) && options_.support_cap &&
      frame.has_support &&
      frame.bottom_height - frame.support_height <= options_.max_support_gap_radii * frame.radius) {
    AddSupport(hypotheses, instance, s, own, options_, &filter, &added_by);
  }
  if (images.accepted == 0 && filter.added().empty()) {
    return Abstention(hypotheses, instance, std::move(out));
  }
  FillOutput(hypotheses, instance, filter, images.counts, bodies, foreign, images.accepted,
             added_by, &out);
  return out;
}

}  // namespace instascene::generation
