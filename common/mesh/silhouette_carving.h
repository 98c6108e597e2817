// common/mesh/silhouette_carving.h: silhouette carving of a fused TSDF volume
// (DepthFusionOptions::carve_views, internal to depth_fusion.cc): each voxel is raised to the
// `carve_views`-th largest outside distance the views' empty pixels give it (in truncations,
// clamped to 1); voxels no view observed that every carving view shows and the capture did not
// see empty are marked in `in_hull` (the renders' visual hull). Parallel over x slabs; the
// result does not depend on the thread count.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include <open3d/pipelines/integration/UniformTSDFVolume.h>
#include <Eigen/Core>

#include "common/mesh/depth_fusion.h"

namespace instascene {

void CarveSilhouettes(const std::vector<DepthView>& views, int carve_views, double sdf_trunc,
                      open3d::pipelines::integration::UniformTSDFVolume* volume,
                      const std::function<bool(const Eigen::Vector3f&)>& seen_empty,
                      std::vector<uint8_t>* in_hull);

}  // namespace instascene
