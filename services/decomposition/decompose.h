// services/decomposition/decompose.h: the decomposition stage as a library (no gRPC):
// trackers -> judgement -> undo -> iterative clustering -> DBSCAN / filtering -> remedy -> export.
//
// Output directory (docs/DECOMPOSITION.md):
//   result.json, labels.ply        the result format of `instascene eval` (one instance per
//   Gaussian;
//                                  where 3D masks overlap, the later instance wins)
//   instances.ply                  element membership: (instance, gaussian) pairs, the full 3D
//   masks decomposition.json             instances with their 2D clusters (view, mask id,
//   coverage), the
//                                  remaining under-segmented masks, the schedule, timings
//   masks_filtered/<view>.png      the input masks with under-segmented masks set to 0
//   masks_sorted/<view>.png        globally consistent instance maps: instance index + 1, 0 = none
// Thread-safe: no shared state.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "common/scene/scene.h"
#include "services/decomposition/options.h"
#include "services/decomposition/post_process.h"

namespace instascene::decomposition {

struct DecompositionResult {
  TrackerSet trackers;
  MaskJudgement judgement;
  std::vector<double> schedule;
  std::vector<Instance> instances;
  std::vector<uint32_t> undersegmented;  // tracker ids that stay under-segmented
  // Per tracker: the mask cluster it ended in (-1: judged under-segmented, never a node); written
  // to decomposition.json so a user can see why a mask was lost.
  std::vector<int32_t> cluster_of;
  int merged_instances = 0;      // merges of unseparated instances
  size_t orphans_labelled = 0;   // traced Gaussians in no instance that joined one
  size_t untraced_labelled = 0;  // untraced Gaussians that joined an instance
  double tracking_seconds = 0, clustering_seconds = 0, post_seconds = 0;

  // One label per Gaussian: instance index + 1 (0 = none; overlaps: the later instance wins).
  std::vector<uint32_t> Labels() const;
};

// Progress: stage name, step, total.
using ProgressFn = std::function<void(const std::string& stage, int done, int total)>;

absl::StatusOr<DecompositionResult> Decompose(const Scene& scene, const GaussianCloud& cloud,
                                              const DecompositionOptions& options,
                                              const ProgressFn& progress = nullptr);

absl::Status WriteDecomposition(const std::string& directory, const Scene& scene,
                                const GaussianCloud& cloud, const DecompositionResult& result);

}  // namespace instascene::decomposition
