// services/generation/viewpoints.h: the viewpoint ring around an object and the occlusion scores
// of any camera (ALGORITHM.md 7.2-7.3). The instance and the occluding scene are ray-cast with
// Embree as surfel discs (common/mesh). A ring view is *known* when more than 75 % of the instance
// points it would see are not hidden by the scene; real training views are ranked by their count
// of unoccluded instance points. Thread-safe after construction.
#pragma once

#include <memory>
#include <vector>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/mesh/ray_caster.h"
#include "common/splat/gaussian_cloud.h"
#include "services/generation/object_frame.h"

namespace instascene::generation {

struct RingOptions {
  int views = 16;               // azimuths, 360 / views degrees apart
  double elevation_deg = 30.0;  // above the object's horizontal plane
  int size_px = 256;            // square images
  double focal_px = 280.0;      // SyncDreamer / MVD-Fusion intrinsics
  double distance_radii = 3.0;  // camera distance in object radii (prototype radius_level)
};

// Cameras looking at frame.center from center + d (cos e cos a, cos e sin a, sin e) in the frame's
// basis, a = k * 360 / views.
std::vector<PinholeCamera> RingCameras(const ObjectFrame& frame, const RingOptions& options);

struct ViewVisibility {
  int self_visible = 0;  // instance sample points the view sees (not hidden by the instance)
  int unoccluded = 0;    // ... of which the scene does not hide either
  double score = 0;      // unoccluded / self_visible (0 when nothing is self-visible)
  bool known = false;    // score > VisibilityOptions::known_threshold
};

struct VisibilityOptions {
  double known_threshold = 0.75;  // ALGORITHM.md 7.3
  // Depth tolerances of the two tests, in object radii (7.3 leaves absolute units open; scaled so
  // the tests do not depend on the scene's unit) and at least 3 instance spacings.
  float self_tolerance_radii = 0.1f;
  float scene_tolerance_radii = 0.1f;
  int max_points = 3000;  // instance points sampled (deterministic stride)
};

class OcclusionScorer {
 public:
  // Builds the two casters (instance discs, occluder discs) for one instance.
  static absl::StatusOr<std::unique_ptr<OcclusionScorer>> Create(const GaussianCloud& cloud,
                                                                 const InstanceSplit& split,
                                                                 const ObjectFrame& frame,
                                                                 const VisibilityOptions& options);
  ViewVisibility Score(const PinholeCamera& camera) const;
  // Indices of `cameras` ordered by unoccluded points (descending, ties by index), at most `top`,
  // only views that see at least one point.
  std::vector<int> RankViews(const std::vector<PinholeCamera>& cameras, int top) const;

  const RayCaster& instance_caster() const { return *instance_; }
  const RayCaster& occluder_caster() const { return *occluders_; }

 private:
  OcclusionScorer() = default;
  VisibilityOptions options_;
  std::vector<Eigen::Vector3f> points_;
  float self_tolerance_ = 0, scene_tolerance_ = 0;
  std::unique_ptr<RayCaster> instance_, occluders_;
};

}  // namespace instascene::generation
