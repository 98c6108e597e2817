// services/training/density_labels.h: the released code's final automatic labelling (ALGORITHM.md
// 5.5, GARField style): HDBSCAN over the trained features of voxel-downsampled Gaussians, labels
// propagated back to every Gaussian. Unlike the tau rule it needs no coarse instances, so objects
// the decomposition merged or missed can still come out as clusters of their own.
//
// Gaussian centres are mapped to [-1, 1] by the robust scene box (2nd-98th percentile, clipped);
// each voxel of side `voxel` keeps the mean of its Gaussians' normalised features and centres; the
// voxel doubles until at most `max_points` voxels remain (the authors allow 1 M on a GPU; the exact
// dense HDBSCAN here is O(n^2), so the CPU default is lower). Each Gaussian takes its voxel's
// cluster; a voxel HDBSCAN calls noise takes the cluster of the nearest clustered voxel (xyz).
// Deterministic for any thread count; thread-safe.
#pragma once

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "common/splat/gaussian_cloud.h"
#include "services/training/hdbscan.h"

namespace instascene::training {

struct DensityLabelOptions {
  HdbscanOptions hdbscan;  // min_samples 30, min_cluster_size 30, epsilon 0.1, single cluster
  double voxel = 0.01;     // in the normalised [-1, 1] box
  int max_points = 12000;  // voxels clustered at most (the voxel doubles until this holds)
};

struct DensityLabels {
  std::vector<uint32_t> labels;  // per Gaussian: cluster + 1 (0 only when nothing clustered)
  size_t clustered_points = 0;   // voxels given to HDBSCAN
  double voxel = 0;              // the voxel side used (normalised units)
  size_t clusters = 0;
};

// features: cloud.size() x dim. InvalidArgument on size mismatch.
absl::StatusOr<DensityLabels> LabelByDensity(const GaussianCloud& cloud,
                                             const std::vector<float>& features, int dim,
                                             const DensityLabelOptions& options);

// The Gaussians the coarse decomposition left as background (coarse label 0) return to the
// background where their cluster is mostly one coarse instance (that instance's Gaussians are at
// least `share` of the cluster): a cluster that is an object the decomposition found keeps its
// object's Gaussians but not the floor it reached through shared voxels (large background
// Gaussians whose centres fall in an object's voxels; docs/RESULTS.md "HDBSCAN labels at
// 320x240"). Clusters of objects the decomposition missed keep everything. share <= 0: nothing
// changes. Returns how many Gaussians returned. coarse and labels: one per Gaussian.
size_t ReturnCoarseBackground(const std::vector<uint32_t>& coarse, double share,
                              std::vector<uint32_t>* labels);

}  // namespace instascene::training
