// services/decomposition/options.h: parameters of the spatial-tracker mask clustering
// (ALGORITHM.md section 4; defaults from zju3dv/InstaScene spatial_track/spatialtrack.py).
#pragma once

#include "absl/status/status.h"
#include "common/core/cancel.h"

namespace instascene::decomposition {

enum class TrackerRule {
  kWeight,  // record (Gaussian, pixel) when w = alpha T > tracker_min_weight (release, default)
  kMedianCrossing,  // record the Gaussian where T crosses 0.5 (paper wording, first public commit)
};

struct DecompositionOptions {
  TrackerRule tracker_rule = TrackerRule::kWeight;
  float tracker_min_weight = 0.1f;  // w threshold of kWeight
  int min_tracker_gaussians = 50;   // smaller trackers (masks) are ignored
  double mask_visible_threshold =
      0.7;  // a frame is skipped if more than this share of the tracker is label 0
  double contained_threshold = 0.8;  // top mask holds more than this share of the non-zero labels
  double undersegment_threshold =
      0.3;  // split frames / visible frames above this = under-segmented
  double view_consensus_threshold = 0.9;  // graph edge if supporter / observer >= this
  double point_filter_threshold = 0.5;    // keep a point if detected / appear > this
  double dbscan_eps = 0.1;                // scene units, or a fraction of the scene extent (below)
  bool dbscan_eps_relative = false;       // eps = dbscan_eps * robust scene diagonal
  int dbscan_min_points = 4;              // Open3D convention: the point itself counts
  double overlap_ratio = 0.8;             // duplicate-object removal
  double remedy_ratio = 0.8;              // under-segmentation remedy
  int num_threads = 0;                    // 0 = all cores; results never depend on it
  const CancelFlag* cancel = nullptr;     // polled per view; not owned (common/core/cancel.h)

  absl::Status Validate() const;
};

}  // namespace instascene::decomposition
