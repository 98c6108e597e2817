#include "services/training/stage_params.h"

#include "absl/strings/str_cat.h"

namespace instascene::training {

absl::StatusOr<Supervision> ParseSupervision(const std::string& name) {
  if (name == "noisy2d") return Supervision::kNoisy2d;
  if (name == "3d") return Supervision::k3d;
  if (name == "3d+filtered2d") return Supervision::k3dFiltered2d;
  if (name == "full") return Supervision::kFull;
  return absl::InvalidArgumentError(
      absl::StrCat("unknown supervision '", name, "' (noisy2d, 3d, 3d+filtered2d, full)"));
}

absl::Status TrainingOptions::Validate() const {
  if (feature_dim < 2 || feature_dim > 64)
    return absl::InvalidArgumentError("feature_dim must be in 2..64");
  if (iterations < 0 || samples < 1 || pixel_pool < 1) {
    return absl::InvalidArgumentError(
        "iterations >= 0, samples >= 1 and pixel_pool >= 1 are required");
  }
  if (!(learning_rate > 0)) return absl::InvalidArgumentError("learning_rate must be positive");
  if (multi_view_every < 1 || multi_view_window < 1)
    return absl::InvalidArgumentError("multi-view settings must be >= 1");
  return absl::OkStatus();
}
absl::Status SegmentStageOptions::Validate() const {
  if (!(threshold > -1.0 && threshold <= 1.0))
    return absl::InvalidArgumentError(absl::StrCat("threshold ", threshold, " is not in (-1, 1]"));
  return absl::OkStatus();
}

const pipeline::ParamCodec<TrainStageOptions>& TrainCodec() {
  using O = TrainStageOptions;
  static const auto* codec = [] {
    auto* c = new pipeline::ParamCodec<O>("train");
    c->Int<int>("iterations", &O::iterations, 1, 1000000, "Optimisation steps")
        .Int<int>("samples", &O::samples, 1, 1 << 20, "Samples per loss term and step")
        .Int<int>("pixel_pool", &O::pixel_pool, 1, 1 << 20, "Traced pixels cached per view")
        .Enum<Supervision>("supervision", &O::supervision,
                           {{"noisy2d", Supervision::kNoisy2d},
                            {"3d", Supervision::k3d},
                            {"3d+filtered2d", Supervision::k3dFiltered2d},
                            {"full", Supervision::kFull}},
                           "Loss terms (paper Table 2)")
        .Bool("ignore_removed_masks", &O::ignore_removed_masks,
              "Single-view term: pixels of masks judged under-segmented are left out instead of "
              "joining the background class (the released code)")
        .Choice("method", &O::method, {"contrastive", "vote"},
                "contrastive (the paper's feature field) or vote (training-free baseline)")
        .Int<uint64_t>("seed", &O::seed, 0, int64_t{1} << 53, "Random seed")
        .Check([](const O& o) { return o.Validate(); });
    return c;
  }();
  return *codec;
}

const pipeline::ParamCodec<SegmentStageOptions>& SegmentCodec() {
  using O = SegmentStageOptions;
  static const auto* codec = [] {
    auto* c = new pipeline::ParamCodec<O>("segment");
    c->Choice("labelling", &O::labelling, {"tau", "hdbscan"},
              "tau (coarse instances select Gaussians by feature similarity, paper) or hdbscan "
              "(density clustering of the features, the released code's final labelling)")
        .Real("threshold", &O::threshold, -1.0, 1.0,
              "Segmentation threshold tau: a Gaussian joins an instance when its feature's "
              "similarity to the instance mean exceeds it")
        .Real("min_kept_share", &O::min_kept_share, 0.0, 1.0,
              "tau: an instance whose features select less than this share of its coarse "
              "Gaussians keeps its coarse mask")
        .Real("max_growth", &O::max_growth, 0.0, 1000.0,
              "tau: an instance whose features select more than this many times its coarse "
              "Gaussians (its mean drifted towards the background's) keeps its coarse mask; 0 = "
              "off")
        .Real("keep_min_dot", &O::keep_min_dot, -1.0, 1.0,
              "tau: a Gaussian of a coarse instance that no instance claims keeps its instance "
              "when its feature matches the instance's mean at least this much and half its "
              "keep_neighbours nearest Gaussians carry the instance")
        .Int("keep_neighbours", &O::keep_neighbours, 0, 64,
             "tau: nearest Gaussians asked by the keep step; 0 = off (the paper's rule)")
        .Real("keep_surrounded", &O::keep_surrounded, 0.0, 2.0,
              "tau: below keep_min_dot, the keep step still keeps a Gaussian when at least this "
              "share of its keep_neighbours nearest Gaussians carry its instance (a tip its "
              "object surrounds); above 1 = off")
        .Int("min_samples", &O::min_samples, 1, 1000, "hdbscan: neighbours of a core point")
        .Int("min_cluster_size", &O::min_cluster_size, 2, 100000, "hdbscan: smallest cluster")
        .Real("cluster_selection_epsilon", &O::cluster_selection_epsilon, 0.0, 2.0,
              "hdbscan: clusters closer than this (feature distance) merge")
        .Real("voxel", &O::voxel, 1e-4, 2.0,
              "hdbscan: voxel side in the scene box normalised to [-1, 1]")
        .Real("coarse_background_share", &O::coarse_background_share, 0.0, 1.0,
              "hdbscan: in a cluster of which one coarse instance holds at least this share, the "
              "Gaussians the decomposition left as background return to the background (0 = off, "
              "the released code)")
        .Int("max_points", &O::max_points, 2, 40000,
             "hdbscan: most voxels clustered (the voxel doubles until this holds; O(n^2) time)")
        .Check([](const O& o) { return o.Validate(); });
    return c;
  }();
  return *codec;
}

pipeline::StageSpec TrainSpec() {
  pipeline::StageSpec spec = pipeline::MakeStageSpec(
      "train", "training",
      "Spatial contrastive feature field on the decomposition (features + coarse labels)",
      {{"decompose", pipeline::InputMode::kOne}}, /*fans_out=*/false, TrainCodec());
  spec.required_outputs = {"result.json", "labels.ply"};
  return spec;
}

pipeline::StageSpec SegmentSpec() {
  pipeline::StageSpec spec = pipeline::MakeStageSpec(
      "segment", "segmentation",
      "Final labels (tau rule or HDBSCAN); one instance PLY per object (its items)",
      {{"train", pipeline::InputMode::kOne}}, /*fans_out=*/true, SegmentCodec());
  spec.required_outputs = {"result.json", "labels.ply", "instances.json"};
  return spec;
}

}  // namespace instascene::training
