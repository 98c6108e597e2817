// services/training/stage_params.h: the `train` and `segment` stages as every binary can link
// them: specs and their one parameter codec each. Light: no rasterizer, no image library.
#pragma once

#include <string>

#include "services/pipeline/stage.h"
#include "services/training/options.h"

namespace instascene::training {

// What a train job takes: the feature field's options and the method.
struct TrainStageOptions : TrainingOptions {
  std::string method = "contrastive";  // or "vote" (training-free baseline)
};

struct SegmentStageOptions {
  // "tau": each coarse instance selects the Gaussians whose feature matches its mean (paper);
  // "hdbscan": density clustering of the features (the released code's final labelling).
  std::string labelling = "tau";
  double threshold = 0.9;          // tau_seg (paper), against the un-normalised mean
  double min_kept_share = 0.25;    // tau: below this share of its coarse mask, an instance keeps it
  double max_growth = 3.0;         // tau: above this many times its coarse mask, likewise (0 = off)
  double keep_min_dot = 0.7;       // tau: SegmentOptions' keep step (an unclaimed Gaussian of a
  int keep_neighbours = 8;         // coarse instance its neighbours carry keeps it; 0 = off)
  double keep_surrounded = 0.875;  // tau: ... whatever its feature, when this share carry it
  // hdbscan (ALGORITHM.md 5.5; max_points bounds the O(n^2) clustering on CPU)
  int min_samples = 30;
  int min_cluster_size = 30;
  double cluster_selection_epsilon = 0.1;
  double voxel = 0.01;
  int max_points = 12000;
  // hdbscan: in a cluster of which one coarse instance holds at least this share, the Gaussians the
  // decomposition left as background return to the background (ReturnCoarseBackground; 0 = off)
  double coarse_background_share = 0.5;
  absl::Status Validate() const;
};

const pipeline::ParamCodec<TrainStageOptions>& TrainCodec();
const pipeline::ParamCodec<SegmentStageOptions>& SegmentCodec();
pipeline::StageSpec TrainSpec();    // input: decompose
pipeline::StageSpec SegmentSpec();  // input: train; fans out (one item per instance)

}  // namespace instascene::training
