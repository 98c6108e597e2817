#include "services/decomposition/stage_params.h"

namespace instascene::decomposition {

absl::Status DecompositionOptions::Validate() const {
  auto in01 = [](double v) { return v >= 0.0 && v <= 1.0; };
  if (!in01(mask_visible_threshold) || !in01(contained_threshold) ||
      !in01(undersegment_threshold) || !in01(view_consensus_threshold) ||
      !in01(point_filter_threshold) || !in01(overlap_ratio) || !in01(remedy_ratio) ||
      !in01(rejudge_min_coverage) || !in01(merge_max_separation) || !in01(uncovered_max_split) ||
      !in01(rejudge_remainder_max_apart)) {
    return absl::InvalidArgumentError("decomposition thresholds must lie in [0, 1]");
  }
  if (!(tracker_min_weight >= 0.0f && tracker_min_weight < 1.0f)) {
    return absl::InvalidArgumentError("tracker_min_weight must lie in [0, 1)");
  }
  if (rejudge_passes < 0 || rejudge_passes > 8)
    return absl::InvalidArgumentError("rejudge_passes must lie in [0, 8]");
  if (!(uncovered_min_labelled >= 0.0 && uncovered_min_labelled <= 2.0))
    return absl::InvalidArgumentError("uncovered_min_labelled must lie in [0, 2]");
  if (!(orphan_min_held >= 0.0 && orphan_min_held <= 2.0))
    return absl::InvalidArgumentError("orphan_min_held must lie in [0, 2]");
  if (merge_min_joins < 0) return absl::InvalidArgumentError("merge_min_joins must be >= 0");
  if (min_tracker_gaussians < 1)
    return absl::InvalidArgumentError("min_tracker_gaussians must be >= 1");
  if (!(dbscan_eps > 0.0) || dbscan_min_points < 1) {
    return absl::InvalidArgumentError("dbscan_eps must be > 0 and dbscan_min_points >= 1");
  }
  return absl::OkStatus();
}

namespace {

using O = DecompositionOptions;

// Steps 1-6 (DECOMPOSITION.md): the mask trackers, the view consensus, the point filter and the
// clustering.
void AddTrackerParams(pipeline::ParamCodec<O>* c) {
  c->Enum("tracker_rule", &O::tracker_rule,
          {{"weight", TrackerRule::kWeight}, {"median", TrackerRule::kMedianCrossing}},
          "weight (w > tracker_min_weight, released code) or median (T crosses 0.5, paper)")
      .Real("tracker_min_weight", &O::tracker_min_weight, 0.0, 0.999,
            "Weight above which a Gaussian joins a mask's tracker")
      .Int("min_tracker_gaussians", &O::min_tracker_gaussians, 1, 1000000000,
           "Smaller mask trackers are ignored")
      .Real("mask_visible_threshold", &O::mask_visible_threshold, 0.0, 1.0,
            "A frame is skipped when more than this share of a tracker is unlabelled there")
      .Real("contained_threshold", &O::contained_threshold, 0.0, 1.0,
            "Top mask share of the non-zero labels that counts as containment")
      .Real("undersegment_threshold", &O::undersegment_threshold, 0.0, 1.0,
            "Split frames / visible frames above this marks an under-segmented mask")
      .Real("view_consensus_threshold", &O::view_consensus_threshold, 0.0, 1.0,
            "Graph edge when supporters / observers reach this")
      .Real("point_filter_threshold", &O::point_filter_threshold, 0.0, 1.0,
            "Keep a Gaussian in an instance when detected / appeared exceeds this")
      .Bool("filter_skips_merged_frames", &O::filter_skips_merged_frames,
            "The point filter does not count frames where the Gaussian lies in a mask judged "
            "under-segmented (false = the released code)")
      .Real("dbscan_eps", &O::dbscan_eps, 1e-9, 1e6,
            "DBSCAN radius: scene units, or a fraction of the scene diagonal when relative")
      .Bool("dbscan_eps_relative", &O::dbscan_eps_relative,
            "Interpret dbscan_eps relative to the robust scene diagonal")
      .Int("dbscan_min_points", &O::dbscan_min_points, 1, 1000000,
           "DBSCAN core size (the point itself counts)")
      .Real("overlap_ratio", &O::overlap_ratio, 0.0, 1.0, "Duplicate-object removal overlap");
}

// Steps 7-11: the remedies for under-segmented masks, the merges and the orphans.
void AddRemedyParams(pipeline::ParamCodec<O>* c) {
  c->Real("remedy_ratio", &O::remedy_ratio, 0.0, 1.0, "Under-segmentation remedy ratio")
      .Int("rejudge_passes", &O::rejudge_passes, 0, 8,
           "Re-judge under-segmented masks against the instances found and recluster, up to "
           "this many times (0 = the released code)")
      .Int("merge_min_joins", &O::merge_min_joins, 0, 1000000,
           "Merge two instances one mask holds together in at least this many frames (and "
           "that masks rarely hold apart); 0 = off (the released code)")
      .Real("merge_max_separation", &O::merge_max_separation, 0.0, 1.0,
            "Largest share of frames holding two instances apart that still allows the merge")
      .Int("merge_glimpse_min", &O::merge_glimpse_min, 0, 1000000,
           "Merge two instances never held apart whose glimpses (frames where one is held, "
           "the other barely traced) put at least this many Gaussians in the held one's mask; "
           "0 = off")
      .Real("rejudge_min_coverage", &O::rejudge_min_coverage, 0.0, 1.0,
            "Share of a mask's tracker that must lie in instances before it is re-judged")
      .Real("uncovered_min_labelled", &O::uncovered_min_labelled, 0.0, 2.0,
            "A flagged mask mostly outside every instance is re-judged sound when masks hold "
            "its Gaussians in at least this share of the frames that trace them (> 1 = off)")
      .Real("uncovered_max_split", &O::uncovered_max_split, 0.0, 1.0,
            "A flagged mask mostly outside every instance is re-judged sound only when split "
            "in at most this share of its visible frames")
      .Real("rejudge_remainder_max_apart", &O::rejudge_remainder_max_apart, 0.0, 1.0,
            "A re-judged mask stays flagged when its part outside every instance and its part "
            "inside one are held apart in more than this share of frames (1 = off)")
      .Real("untraced_radius", &O::untraced_radius, 0.0, 1.0,
            "A Gaussian no view traces joins the instance of the nearest traced Gaussian "
            "within this share of the robust scene diagonal (0 = off, the released code)")
      .Real("orphan_min_held", &O::orphan_min_held, 0.0, 2.0,
            "A traced Gaussian in no instance joins an instance that its masks hold in at "
            "least this share of the frames tracing it, grown in untraced_radius steps (> 1 "
            "or untraced_radius 0 = off, the released code)")
      .Bool("orphan_skips_missed_frames", &O::orphan_skips_missed_frames,
            "The orphan share does not count frames where the segmenter missed the candidate "
            "instance (most of it traced there in no mask); false = every traced frame counts")
      .Real("observer_floor", &O::observer_floor, 0.0, 1000.0,
            "The observer schedule ends with this threshold when it stopped above it (<= 1 = "
            "off, the released code)");
}

}  // namespace

const pipeline::ParamCodec<DecompositionOptions>& DecomposeCodec() {
  static const auto* codec = [] {
    auto* c = new pipeline::ParamCodec<O>("decompose");
    AddTrackerParams(c);
    AddRemedyParams(c);
    c->Check([](const O& o) { return o.Validate(); });
    return c;
  }();
  return *codec;
}

pipeline::StageSpec DecomposeSpec() {
  pipeline::StageSpec spec = pipeline::MakeStageSpec(
      "decompose", "decomposition",
      "Spatial Gaussian trackers + view-consensus mask clustering: coarse 3D instances", {},
      /*fans_out=*/false, DecomposeCodec());
  spec.required_outputs = {"result.json", "labels.ply", "decomposition.json"};
  return spec;
}

}  // namespace instascene::decomposition
