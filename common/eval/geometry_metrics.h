// common/eval/geometry_metrics.h: completion metrics (ALGORITHM.md section 8): Chamfer distance,
// precision / recall / F1 at a distance threshold, volume IoU of closed meshes on a voxel grid.
// Pure functions, thread-safe.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "common/geometry/triangle_mesh.h"

namespace instascene {

struct PointCloudComparison {
  double chamfer = 0;  // (mean_p min_q |p - q| + mean_q min_p |q - p|) / 2 (SyncDreamer convention)
  double precision = 0;  // fraction of predicted points within tau of the ground truth
  double recall = 0;     // fraction of ground-truth points within tau of the prediction
  double f1 = 0;         // 2 P R / (P + R)
};

// Both clouds in the same (scene-aligned) frame; tau in the same units. Default tau used by the
// project: 1 % of the ground truth bounding-box diagonal (docs/EVALUATION.md).
PointCloudComparison ComparePointClouds(const std::vector<Eigen::Vector3f>& predicted,
                                        const std::vector<Eigen::Vector3f>& ground_truth,
                                        double tau);

// Volume IoU of two closed meshes voxelised on a resolution^3 grid over their joint bounding box;
// a voxel is inside when its centre is (ray parity along +x). SyncDreamer uses 64^3.
double VolumeIou(const TriangleMesh& a, const TriangleMesh& b, int resolution = 64);

// Inside/outside of grid voxel centres for one closed mesh (exposed for tests).
std::vector<uint8_t> VoxelizeClosedMesh(const TriangleMesh& mesh, const Eigen::AlignedBox3f& box,
                                        int resolution);

// Area-uniform samples on a mesh surface (deterministic from seed), e.g. for Chamfer on meshes.
std::vector<Eigen::Vector3f> SampleSurface(const TriangleMesh& mesh, size_t count, uint64_t seed);

}  // namespace instascene
