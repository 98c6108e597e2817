// common/mesh/surface_distance.h: the exact unsigned distance from points to a triangle mesh.
//
// Open3D's RaycastingScene answers it with a closest-point query on its BVH (chosen over a
// hand-written point-triangle routine on Embree's rtcPointQuery: the same result, kept by
// Open3D). Evaluations use it where a sampled stand-in for the surface would add the samples'
// spacing to every distance (EVALUATION.md, free-space violations). Thread-safe: Distances
// serialises calls on one instance.
#pragma once

#include <memory>
#include <mutex>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "common/geometry/triangle_mesh.h"

namespace open3d::t::geometry {
class RaycastingScene;
}

namespace instascene {

class SurfaceDistance {
 public:
  // InvalidArgument for a mesh with no triangles or an index out of range.
  static absl::StatusOr<std::unique_ptr<SurfaceDistance>> Create(const TriangleMesh& mesh);
  ~SurfaceDistance();
  SurfaceDistance(const SurfaceDistance&) = delete;
  SurfaceDistance& operator=(const SurfaceDistance&) = delete;

  // The distance from each point to the nearest point of the mesh's surface.
  std::vector<float> Distances(const std::vector<Eigen::Vector3f>& points) const;

 private:
  SurfaceDistance();
  std::unique_ptr<open3d::t::geometry::RaycastingScene> scene_;
  mutable std::mutex mutex_;
};

}  // namespace instascene
