#include "services/generation/viewpoints.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numeric>

#include "common/core/status.h"
#include "common/mesh/surfel_mesh.h"

namespace instascene::generation {

std::vector<PinholeCamera> RingCameras(const ObjectFrame& frame, const RingOptions& options) {
  const Eigen::Matrix3f basis = frame.Basis();
  std::vector<PinholeCamera> cameras;
  for (int k = 0; k < options.views; ++k) {
    const double azimuth = 360.0 * k / options.views;
    // The position in the frame's basis (so azimuth 0 is the basis' x), looking at the centre.
    const double a = azimuth * M_PI / 180.0, e = options.elevation_deg * M_PI / 180.0;
    const Eigen::Vector3d offset =
        (basis.cast<double>() *
         Eigen::Vector3d(std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e)));
    const double distance = options.distance_radii * std::max(frame.radius, 1e-6f);
    const Eigen::Vector3d center = frame.center.cast<double>();
    const Eigen::Vector3d eye = center + distance * offset;
    const Eigen::Vector3d forward = (center - eye).normalized();
    const Eigen::Vector3d up = frame.up.cast<double>();
    Eigen::Vector3d right = forward.cross(up);
    if (right.norm() < 1e-9) right = basis.col(0).cast<double>();
    right.normalize();
    const Eigen::Vector3d down = forward.cross(right);
    PinholeCamera camera;
    camera.width = camera.height = options.size_px;
    camera.fx = camera.fy = options.focal_px;
    camera.cx = camera.cy = 0.5 * options.size_px;
    camera.camera_from_world.rotation.row(0) = right.transpose();
    camera.camera_from_world.rotation.row(1) = down.transpose();
    camera.camera_from_world.rotation.row(2) = forward.transpose();
    camera.camera_from_world.translation = -(camera.camera_from_world.rotation * eye);
    cameras.push_back(camera);
  }
  return cameras;
}

absl::StatusOr<std::unique_ptr<OcclusionScorer>> OcclusionScorer::Create(
    const GaussianCloud& cloud, const InstanceSplit& split, const ObjectFrame& frame,
    const VisibilityOptions& options) {
  std::unique_ptr<OcclusionScorer> scorer(new OcclusionScorer());
  scorer->options_ = options;
  const size_t stride = std::max<size_t>(
      1, split.instance.size() / static_cast<size_t>(std::max(1, options.max_points)));
  for (size_t i = 0; i < split.instance.size(); i += stride) {
    scorer->points_.emplace_back(&cloud.positions[3 * split.instance[i]]);
  }
  scorer->self_tolerance_ =
      std::max(options.self_tolerance_radii * frame.radius, 3.0f * frame.spacing);
  scorer->scene_tolerance_ =
      std::max(options.scene_tolerance_radii * frame.radius, 3.0f * frame.spacing);
  const SurfelDiscOptions discs;
  ASSIGN_OR_RETURN(scorer->instance_, RayCaster::Create(SurfelDiscs(cloud, split.instance, discs)));
  ASSIGN_OR_RETURN(scorer->occluders_,
                   RayCaster::Create(SurfelDiscs(cloud, split.occluders, discs)));
  return scorer;
}

ViewVisibility OcclusionScorer::Score(const PinholeCamera& camera) const {
  const Eigen::Vector3f origin = camera.CenterInWorld().cast<float>();
  std::atomic<int> self_visible{0}, unoccluded{0};
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, points_.size(), 256),
      [&](const tbb::blocked_range<size_t>& range) {
        int self = 0, clear = 0;
        for (size_t i = range.begin(); i != range.end(); ++i) {
          const Eigen::Vector3f& p = points_[i];
          if (!camera.SeesPoint(p.cast<double>())) continue;
          const Eigen::Vector3f offset = p - origin;
          const float line = offset.norm();
          const Eigen::Vector3f dir = offset / line;
          const RayHit own = instance_->Cast(origin, dir);
          if (!own.hit || std::abs(own.distance - line) > self_tolerance_) continue;
          ++self;
          if (!occluders_->Cast(origin, dir, 0.0f, std::max(0.0f, line - scene_tolerance_)).hit)
            ++clear;
        }
        self_visible += self;
        unoccluded += clear;
      });
  ViewVisibility out;
  out.self_visible = self_visible.load();
  out.unoccluded = unoccluded.load();
  out.score = out.self_visible > 0 ? static_cast<double>(out.unoccluded) / out.self_visible : 0.0;
  out.known = out.score > options_.known_threshold;
  return out;
}

std::vector<int> OcclusionScorer::RankViews(const std::vector<PinholeCamera>& cameras,
                                            int top) const {
  std::vector<int> seen(cameras.size());
  for (size_t c = 0; c < cameras.size(); ++c) seen[c] = Score(cameras[c]).unoccluded;
  std::vector<int> order;
  for (size_t c = 0; c < cameras.size(); ++c) {
    if (seen[c] > 0) order.push_back(static_cast<int>(c));
  }
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return seen[a] > seen[b]; });
  if (static_cast<int>(order.size()) > top) order.resize(top);
  return order;
}

}  // namespace instascene::generation
