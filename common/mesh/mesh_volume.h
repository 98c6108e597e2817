// common/mesh/mesh_volume.h: inside/outside of grid voxel centres for a closed mesh, robust to the
// meshes marching cubes produces. Rows of voxels are classified by the parity of Embree's
// watertight ray crossings (a ray through a shared edge hits exactly one of its triangles, which a
// hand-written ray/triangle parity test does not guarantee) along x, y and z; a voxel is inside
// when at least two of the three agree. Used for volume IoU. Thread-safe.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Geometry>

#include "absl/status/statusor.h"
#include "common/geometry/triangle_mesh.h"

namespace instascene {

// resolution^3 voxels over `box`, index (k * r + j) * r + i for cell (i, j, k) along (x, y, z).
absl::StatusOr<std::vector<uint8_t>> VoxelizeByRayParity(const TriangleMesh& mesh,
                                                         const Eigen::AlignedBox3f& box,
                                                         int resolution);

}  // namespace instascene
