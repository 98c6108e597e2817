// services/generation/free_space.h: the space real views saw empty around an object (the ray
// segments in front of the first surface, ALGORITHM.md 7.8 and GENERATION.md step 4). A completion
// may never put surface there. A voxel grid over the cube centre +- extent * radius; a voxel is
// free when at least `min_views` views saw through it. Immutable after Carve; thread-safe reads.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/mesh/ray_caster.h"
#include "services/generation/object_frame.h"

namespace instascene::generation {

struct FreeSpaceOptions {
  int resolution = 64;         // voxels per axis
  float extent_radii = 2.0f;   // half-size of the grid cube, in object radii
  int min_views = 2;           // views that must see through a voxel for it to be free
  float margin_voxels = 1.5f;  // stop this far in front of the first surface
  int max_rays_per_view = 40000;
  // Holes between surfel discs: a ray is a hole when all but hole_slack of its neighbours (within
  // hole_rays rays) stop more than the margin before it; it then stops where the farthest of
  // those does, so that a ray slipping through the model does not carve its inside (0 = off).
  // Measured in RESULTS.md ("Free-space violations").
  int hole_rays = 1;
  int hole_slack = 3;
};

class FreeSpaceGrid {
 public:
  // Casts rays of every camera against `surfaces` (the whole scene: instance and occluders).
  static absl::StatusOr<FreeSpaceGrid> Carve(const std::vector<PinholeCamera>& cameras,
                                             const RayCaster& surfaces, const ObjectFrame& frame,
                                             const FreeSpaceOptions& options);

  // True when `p` is inside the grid and was seen empty by at least min_views views.
  bool IsFree(const Eigen::Vector3f& p) const;
  // Views that saw the voxel containing p empty (0 outside the grid).
  int FreeViews(const Eigen::Vector3f& p) const;
  float voxel() const { return voxel_; }
  int resolution() const { return resolution_; }
  double FreeFraction() const;  // share of the grid's voxels that are free

 private:
  int64_t VoxelOf(const Eigen::Vector3f& p) const;  // -1 outside
  // The voxels one camera's rays cross before the surfaces (1 = seen empty).
  std::vector<uint8_t> SeenFrom(const PinholeCamera& camera, const RayCaster& surfaces,
                                const ObjectFrame& frame, const FreeSpaceOptions& options) const;
  Eigen::Vector3f origin_ = Eigen::Vector3f::Zero();
  float voxel_ = 0;
  int resolution_ = 0;
  int min_views_ = 1;
  std::vector<uint16_t> free_views_;
};

}  // namespace instascene::generation
