#include "common/mesh/mesh_volume.h"

#include <tbb/parallel_for.h>

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/mesh/ray_caster.h"

namespace instascene {

absl::StatusOr<std::vector<uint8_t>> VoxelizeByRayParity(const TriangleMesh& mesh,
                                                         const Eigen::AlignedBox3f& box,
                                                         int resolution) {
  const int r = resolution;
  if (r < 1 || r > 1024 || box.isEmpty()) {
    return absl::InvalidArgumentError(absl::StrCat("voxelize: bad grid (resolution ", r, ")"));
  }
  ASSIGN_OR_RETURN(std::unique_ptr<RayCaster> caster, RayCaster::Create(mesh));
  const Eigen::Vector3f cell = box.sizes() / static_cast<float>(r);
  std::vector<uint8_t> votes(static_cast<size_t>(r) * r * r, 0);
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    // Each row (a, b) is written by one task: disjoint voxels, no race.
    tbb::parallel_for(0, r * r, [&](int row) {
      const int a = row % r, b = row / r;
      Eigen::Vector3f origin;
      origin[axis] = box.min()[axis] - cell[axis];
      origin[u] = box.min()[u] + (a + 0.5f) * cell[u];
      origin[v] = box.min()[v] + (b + 0.5f) * cell[v];
      Eigen::Vector3f dir = Eigen::Vector3f::Zero();
      dir[axis] = 1.0f;
      const std::vector<float> hits = caster->AllHits(origin, dir);
      size_t next = 0;
      for (int c = 0; c < r; ++c) {
        const float t = cell[axis] * (c + 1.5f);  // distance of the voxel centre from the origin
        while (next < hits.size() && hits[next] < t) ++next;
        if (next % 2 == 0) continue;  // an even number of crossings before it: outside
        Eigen::Vector3i index;
        index[axis] = c;
        index[u] = a;
        index[v] = b;
        ++votes[(static_cast<size_t>(index.z()) * r + index.y()) * r + index.x()];
      }
    });
  }
  for (uint8_t& vote : votes) vote = vote >= 2;
  return votes;
}

}  // namespace instascene
