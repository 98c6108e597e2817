// services/training/segmentation.h: from trained features to instances (ALGORITHM.md 5.5):
// per coarse 3D instance the mean of its Gaussians' normalised features (not re-normalised), every
// Gaussian assigned to the instance whose mean it matches best if the dot product reaches tau = 0.9
// (else background), instances that select nothing keep their coarse Gaussians; export of
// full-attribute per-instance PLY files, a labelled scene PLY and a manifest.
// Pure functions / file writers; thread-safe.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "common/eval/result.h"
#include "common/splat/gaussian_cloud.h"
#include "services/training/feature_field.h"
#include "services/training/stage_params.h"

namespace instascene::training {

struct SegmentOptions {
  double threshold = 0.9;  // paper tau_seg, against the un-normalised mean
  // An instance whose features select fewer than this share of its coarse Gaussians was not held
  // apart by the feature field (under-trained, or a look-alike neighbour took it over): it keeps
  // its coarse mask instead of vanishing into a sliver.
  double min_kept_share = 0.25;
  // An instance whose features select more than this many times its coarse Gaussians has a mean
  // that drifted towards the background's (a small or spurious coarse instance whose features
  // were not held apart): it keeps its coarse mask instead of spreading over the scene. 0 = off.
  double max_growth = 3.0;
  // A Gaussian of a coarse instance that no instance's mean claims at tau (it would fall to the
  // background) keeps its coarse instance when its feature still matches that instance's mean at
  // least `keep_min_dot` and at least half of its `keep_neighbours` nearest Gaussians (centres)
  // carry the instance; repeated while it keeps more (a rim or an edge seen in few views, whose
  // features were trained less, stays with its object; docs/RESULTS.md "Unclaimed Gaussians of a
  // coarse instance"). keep_neighbours 0 = off (the paper's rule).
  double keep_min_dot = 0.7;
  int keep_neighbours = 8;
  // Below keep_min_dot, a Gaussian of a coarse instance still keeps it when at least this share
  // of its keep_neighbours nearest Gaussians carry the instance (surrounded by its object: a
  // cone's tip); > 1 = off.
  double keep_surrounded = 0.875;
};

// labels: per Gaussian, the coarse instance id (0 = none) used to define the instances;
// positions: 3 per Gaussian (centres), for the keep step (empty: the step is skipped). Returns the
// final per-Gaussian labels with the same ids. Deterministic.
std::vector<uint32_t> SegmentByFeatures(const std::vector<float>& features, int dim,
                                        const std::vector<uint32_t>& coarse,
                                        const std::vector<float>& positions,
                                        const SegmentOptions& options);

// The segmentation result of a training run: labels by the tau rule over the coarse instances,
// the raw features kept for click queries and evaluation.
SegmentationResult TrainedResult(const TrainingResult& trained, const TrainingData& data,
                                 const GaussianCloud& cloud, int dim,
                                 const SegmentOptions& options);

// Final labels of a trained result (features + coarse labels) by the segment stage's labelling;
// what was done goes into `metadata`.
absl::StatusOr<std::vector<uint32_t>> FinalLabels(const SegmentationResult& trained,
                                                  const GaussianCloud& cloud,
                                                  const SegmentStageOptions& options,
                                                  int num_threads, nlohmann::json* metadata);

// instances/<id>.ply (every original property), instances/background.ply (label 0, when any),
// scene_labelled.ply (+ instance_id), instances.json.
absl::Status ExportInstances(const std::string& directory, const GaussianCloud& cloud,
                             const std::vector<uint32_t>& labels);

}  // namespace instascene::training
