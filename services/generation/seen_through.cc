#include "services/generation/seen_through.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/geometry/rigid.h"
#include "common/mesh/surfel_mesh.h"

namespace instascene::generation {

absl::Status SeenThroughOptions::Validate() const {
  if (!(min_opacity > 0) || !(min_opacity < 1) || !(blocked_below > 0) || !(blocked_below < 1) ||
      !(tolerance_radii >= 0) || !(extent_sigma > 0) || !(extent_sigma <= 4) || max_crossings < 1 ||
      max_crossings > 4096 || !(core_sigma > 0) || !(core_sigma <= extent_sigma) ||
      core_views < 0 || core_views > 1000 || !(rim_depth_radii >= 0) || !(rim_depth_radii <= 2)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "seen-through test: bad options (min_opacity ", min_opacity, ", blocked_below ",
        blocked_below, ", extent_sigma ", extent_sigma, ", tolerance ", tolerance_radii,
        ", max_crossings ", max_crossings, ", core_sigma ", core_sigma, ", core_views ", core_views,
        ", rim_depth_radii ", rim_depth_radii, ")"));
  }
  return absl::OkStatus();
}

absl::StatusOr<SeenThroughTest> SeenThroughTest::Create(const std::vector<PinholeCamera>& cameras,
                                                        const GaussianCloud& scene, float radius,
                                                        const SeenThroughOptions& options) {
  RETURN_IF_ERROR(options.Validate());
  if (scene.num_scales != 2) return absl::InvalidArgumentError("seen-through test: needs surfels");
  if (!(radius > 0)) return absl::InvalidArgumentError("seen-through test: radius is not > 0");
  SeenThroughTest out;
  out.cameras_ = cameras;
  out.options_ = options;
  out.tolerance_ = options.tolerance_radii * radius;
  out.rim_depth_ = options.rim_depth_radii * radius;
  // The surfels that make discs (the same at every extent), compacted in scene order.
  std::vector<int64_t> compact(scene.size(), -1);
  auto make_discs = [&](float extent_sigma) -> absl::StatusOr<Discs> {
    SurfelDiscOptions options_discs;
    options_discs.min_opacity = options.min_opacity;
    options_discs.extent_sigma = extent_sigma;
    std::vector<uint32_t> source;
    const TriangleMesh mesh = SurfelDiscs(scene, {}, options_discs, &source);
    Discs discs;
    ASSIGN_OR_RETURN(discs.caster, RayCaster::Create(mesh));
    discs.triangle_surfel.reserve(source.size());
    for (uint32_t g : source) {
      if (compact[g] < 0) {
        compact[g] = static_cast<int64_t>(out.surfels_.size());
        const float* q = &scene.rotations[4 * g];
        const Eigen::Matrix3f r = RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]).cast<float>();
        const float* ls = &scene.log_scales[2 * g];
        Surfel s;
        s.center = Eigen::Vector3f(&scene.positions[3 * g]);
        s.u = r.col(0) / std::max(std::exp(ls[0]), 1e-12f);
        s.v = r.col(1) / std::max(std::exp(ls[1]), 1e-12f);
        s.opacity = 1.0f / (1.0f + std::exp(-scene.opacity_logits[g]));
        out.surfels_.push_back(s);
      }
      discs.triangle_surfel.push_back(static_cast<uint32_t>(compact[g]));
    }
    return discs;
  };
  ASSIGN_OR_RETURN(out.discs_, make_discs(options.extent_sigma));
  if (options.core_views > 0) {
    ASSIGN_OR_RETURN(out.core_discs_, make_discs(options.core_sigma));
  }
  return out;
}

float SeenThroughTest::Transmittance(const Eigen::Vector3f& origin,
                                     const Eigen::Vector3f& direction, float t_far,
                                     bool core) const {
  const Discs& discs = core && core_discs_.caster ? core_discs_ : discs_;
  float transmittance = 1.0f;
  float t = 0.0f;
  // Each crossing attenuates by the surfel's alpha there (2DGS's clamp at 0.99); the next cast
  // starts just past it (a disc is planar: it is crossed once).
  const float step = 1e-6f * std::max(1.0f, t_far);
  for (int crossing = 0; crossing < options_.max_crossings; ++crossing) {
    const RayHit hit = discs.caster->Cast(origin, direction, t, t_far);
    if (!hit.hit) return transmittance;
    const Surfel& s = surfels_[discs.triangle_surfel[hit.triangle]];
    const Eigen::Vector3f d = origin + hit.distance * direction - s.center;
    const float a = d.dot(s.u), b = d.dot(s.v);
    const float alpha = std::min(0.99f, s.opacity * std::exp(-0.5f * (a * a + b * b)));
    transmittance *= 1.0f - alpha;
    if (transmittance < options_.blocked_below) return transmittance;
    t = hit.distance + step;
  }
  return 0.0f;
}

bool PixelFootprint(const PinholeCamera& c, const Eigen::Vector3f& p,
                    std::array<Eigen::Vector3f, 5>* points) {
  Eigen::Vector3d in_camera;
  if (!c.SeesPoint(p.cast<double>(), &in_camera)) return false;
  const Eigen::Matrix3d to_world = c.camera_from_world.rotation.transpose();
  const double half_x = 0.5 * in_camera.z() / c.fx, half_y = 0.5 * in_camera.z() / c.fy;
  const Eigen::Vector3d offsets[5] = {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(half_x, 0, 0),
                                      Eigen::Vector3d(-half_x, 0, 0), Eigen::Vector3d(0, half_y, 0),
                                      Eigen::Vector3d(0, -half_y, 0)};
  for (int k = 0; k < 5; ++k) (*points)[k] = p + (to_world * offsets[k]).cast<float>();
  return true;
}

bool SeenThroughTest::ViewSeesThrough(const PinholeCamera& c, const Eigen::Vector3f& p,
                                      bool core) const {
  std::array<Eigen::Vector3f, 5> footprint;
  if (!PixelFootprint(c, p, &footprint)) return false;
  const Eigen::Vector3f eye = c.CenterInWorld().cast<float>();
  for (const Eigen::Vector3f& q : footprint) {
    const float line = (q - eye).norm();
    if (Transmittance(eye, (q - eye) / line, line + tolerance_, core) < options_.blocked_below) {
      return false;  // this ray of the footprint stopped at or before p (or just behind it)
    }
  }
  return true;
}

int SeenThroughTest::ViewsSeeingThrough(const Eigen::Vector3f& p, int enough, bool core) const {
  int count = 0;
  for (const PinholeCamera& c : cameras_) {
    if (ViewSeesThrough(c, p, core) && ++count >= enough) break;
  }
  return count;
}

int SeenThroughTest::SeenSide(const Eigen::Vector3f& p, const Eigen::Vector3f& n) const {
  float vote = 0;
  for (const PinholeCamera& c : cameras_) {
    if (!c.SeesPoint(p.cast<double>())) continue;
    const Eigen::Vector3f eye = c.CenterInWorld().cast<float>();
    const float line = (p - eye).norm();
    if (!(line > tolerance_)) continue;
    const Eigen::Vector3f dir = (p - eye) / line;
    if (Transmittance(eye, dir, line - tolerance_) < options_.blocked_below) continue;
    vote -= dir.dot(n);
  }
  return vote > 0 ? 1 : vote < 0 ? -1 : 0;
}

bool SeenThroughTest::ViewSeesPastRim(const PinholeCamera& c, const Eigen::Vector3f& p) const {
  std::array<Eigen::Vector3f, 5> footprint;
  if (!PixelFootprint(c, p, &footprint)) return false;
  const Eigen::Vector3f eye = c.CenterInWorld().cast<float>();
  for (const Eigen::Vector3f& q : footprint) {
    const float line = (q - eye).norm();
    const Eigen::Vector3f direction = (q - eye) / line;
    if (Transmittance(eye, direction, line - rim_depth_) < options_.blocked_below ||
        Transmittance(eye, direction, line + tolerance_, true) < options_.blocked_below) {
      return false;
    }
  }
  return true;
}

bool SeenThroughTest::SeenThrough(const Eigen::Vector3f& p) const {
  if (ViewsSeeingThrough(p) > 0) return true;
  if (core_discs_.caster == nullptr) return false;
  if (ViewsSeeingThrough(p, options_.core_views, true) >= options_.core_views) return true;
  if (!(rim_depth_ > 0)) return false;
  for (const PinholeCamera& c : cameras_) {
    if (ViewSeesPastRim(c, p)) return true;
  }
  return false;
}

}  // namespace instascene::generation
