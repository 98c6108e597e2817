// common/mesh/ray_caster.h: ray casting against a triangle mesh with Embree 3.
//
// Used for the occlusion scores of the viewpoint ring, the free space real views carve, and mesh
// volume tests (ALGORITHM.md 7.3, 7.7, 7.8). One Embree device per process; a RayCaster owns its
// committed scene and copies of the mesh buffers. Embree errors are caught here and turned into a
// Status (the only place this project talks to Embree). Thread-safe: Cast may be called from many
// threads at once.
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "common/geometry/triangle_mesh.h"

namespace instascene {

struct RayHit {
  bool hit = false;
  float distance = std::numeric_limits<float>::infinity();  // along the (unit) direction
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();  // unit geometric normal, (v1-v0)x(v2-v0)
  uint32_t triangle = 0;                             // index into the mesh's triangles
};

class RayCaster {
 public:
  // Builds the BVH over `mesh` (robust build: watertight meshes give watertight casts). Fails on a
  // mesh with an out-of-range index or a non-finite vertex, or when Embree fails.
  static absl::StatusOr<std::unique_ptr<RayCaster>> Create(const TriangleMesh& mesh);
  ~RayCaster();
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  // The first hit along origin + t * direction for t in [t_near, t_far]; `direction` must be
  // unit length for `distance` to be metric. An empty mesh never hits.
  RayHit Cast(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction, float t_near = 0.0f,
              float t_far = std::numeric_limits<float>::infinity()) const;

  // Number of surface crossings along the whole ray (t >= t_near): counts every hit by stepping
  // past it. Used for inside/outside tests by parity.
  int CountCrossings(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction,
                     float t_near = 0.0f) const;

  // Distances of every surface crossing along the ray (t >= t_near), increasing.
  std::vector<float> AllHits(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction,
                             float t_near = 0.0f) const;

  size_t num_triangles() const { return num_triangles_; }

 private:
  RayCaster() = default;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  size_t num_triangles_ = 0;
};

}  // namespace instascene
