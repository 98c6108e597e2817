// services/decomposition/post_process.h: from mask clusters to 3D instances (ALGORITHM.md 4.7-4.8):
// DBSCAN splitting of every cluster's Gaussians, the detection-ratio point filter, removal of
// contained duplicates, and the remedy for masks wrongly flagged as under-segmented.
// Deterministic; thread-safe (no shared state).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Geometry>

#include "common/splat/gaussian_cloud.h"
#include "services/decomposition/mask_graph.h"

namespace instascene::decomposition {

struct Instance {
  std::vector<uint32_t> gaussians;  // sorted: the 3D instance mask M^3d
  std::vector<uint32_t> masks;      // tracker ids of its 2D cluster
  std::vector<float> coverage;      // per mask: overlap / |instance| at assignment (remedied: 1)
  Eigen::AlignedBox3f box;          // of the unfiltered sub-object points
};

// Robust diagonal of the Gaussian centres (2nd-98th percentile box), for scene-relative constants.
float RobustSceneDiagonal(const GaussianCloud& cloud);

// `undersegmented` (per tracker, may be null): the masks judged merges, whose frames the point
// filter skips (DecompositionOptions::filter_skips_merged_frames).
std::vector<Instance> BuildInstances(const TrackerSet& trackers, const std::vector<MaskNode>& nodes,
                                     const GaussianCloud& cloud,
                                     const DecompositionOptions& options,
                                     const std::vector<uint8_t>* undersegmented = nullptr);

// 4.8: under-segmented masks whose tracker lies > remedy_ratio inside one instance join that
// instance's 2D cluster; returns the masks that remain under-segmented.
std::vector<uint32_t> RemedyUndersegmented(const TrackerSet& trackers,
                                           const MaskJudgement& judgement,
                                           const DecompositionOptions& options,
                                           std::vector<Instance>* instances);

}  // namespace instascene::decomposition
