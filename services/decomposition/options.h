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
  int min_tracker_gaussians = 30;   // smaller trackers are ignored (release: 50; DECOMPOSITION.md)
  double mask_visible_threshold =
      0.7;  // a frame is skipped if more than this share of the tracker is label 0
  double contained_threshold = 0.8;  // top mask holds more than this share of the non-zero labels
  double undersegment_threshold =
      0.3;  // split frames / visible frames above this = under-segmented
  double view_consensus_threshold = 0.9;  // graph edge if supporter / observer >= this
  double point_filter_threshold = 0.5;    // keep a point if detected / appear > this
  // Not in the released code (docs/DECOMPOSITION.md): the point filter does not count a frame
  // where the point lies in a mask judged under-segmented (merged with a neighbour): with frequent
  // merges an object's own points fall below the threshold and leave it.
  bool filter_skips_merged_frames = true;
  // Not in the released code (docs/DECOMPOSITION.md): the observer schedule ends with this
  // threshold when it stopped above it (its percentiles stop at the first value <= 1 below the
  // median), so that the masks of an object seen together in only this many frames (a small
  // object the segmenter misses in most views) still cluster. <= 1 = off (the released code).
  double observer_floor = 2;
  double dbscan_eps = 0.1;           // scene units, or a fraction of the scene extent (below)
  bool dbscan_eps_relative = false;  // eps = dbscan_eps * robust scene diagonal
  int dbscan_min_points = 4;         // Open3D convention: the point itself counts
  double overlap_ratio = 0.8;        // duplicate-object removal
  double remedy_ratio = 0.8;         // under-segmentation remedy
  // Re-judgement (not in the released code; docs/DECOMPOSITION.md): after clustering, a mask
  // judged under-segmented whose Gaussians lie mostly in one instance (>= remedy_ratio of those
  // inside any instance, and those >= rejudge_min_coverage of the tracker) was split by other
  // views' part masks, not a merge: it is restored and the clustering reruns, up to this many
  // times.
  int rejudge_passes = 3;
  double rejudge_min_coverage = 0.5;
  // A flagged mask lying mostly outside every instance (below rejudge_min_coverage) is restored
  // too when the masks hold its Gaussians in >= uncovered_min_labelled of the frames that trace
  // them (a segmenter masks an object wherever it sees it, stray background only now and then)
  // and it was split in at most uncovered_max_split of its visible frames (a whole object's mask
  // split by part masks in a minority of views; a merge is split wherever its objects are masked
  // apart). Restores objects whose every whole mask other views' part masks flagged.
  // uncovered_min_labelled > 1 = off.
  double uncovered_min_labelled = 0.8;
  double uncovered_max_split = 0.5;
  // A flagged mask that the rule above would restore keeps its flag when the part of its tracker
  // outside every instance (at least min_tracker_gaussians) and the part inside its instance are
  // held apart by different masks in more than this share of the frames where masks hold both:
  // that part is another object the clustering never found (a bottle merged into a torus's
  // masks), not the rest of the instance's object. 1 = off.
  double rejudge_remainder_max_apart = 0.5;
  // Merging of unseparated instances (not in the released code; docs/DECOMPOSITION.md): two
  // instances that one mask holds together in >= merge_min_joins frames and that separate masks
  // hold apart in at most merge_max_separation of the frames where both are contained are one
  // object seen from two sides. 0 joins = off.
  int merge_min_joins = 2;
  double merge_max_separation = 0.25;
  // Glimpses (DECOMPOSITION.md step 8): in a frame where one of two instances is held and the
  // other is traced in fewer than min_tracker_gaussians Gaussians, where that other's Gaussians
  // lie: in the held one's mask or in other masks. Two instances that no frame holds apart, whose
  // glimpses put at least this many Gaussians in the other's mask and at most
  // merge_max_separation of them elsewhere, are one object seen from two arcs of views that meet
  // nowhere (a cone's front in the first views, its back in the last). 0 = off (and with
  // merge_min_joins 0: no merging at all, as in the released code).
  int merge_glimpse_min = 20;
  // Labelling of untraced Gaussians (not in the released code; docs/DECOMPOSITION.md): a
  // Gaussian that no view traces joins the instance of the nearest traced Gaussian within this
  // share of the robust scene diagonal. 0 = off.
  double untraced_radius = 0.01;
  // Labelling of orphan Gaussians (not in the released code; docs/DECOMPOSITION.md): a traced
  // Gaussian in no instance joins an instance that its masks hold in at least this share of the
  // frames that trace it; instances grow through such Gaussians in steps of untraced_radius, so
  // the nearest along them wins when several qualify. > 1 (or untraced_radius 0) = off.
  double orphan_min_held = 0.5;
  // ... counting, per candidate instance, only the frames where the segmenter did not miss that
  // instance (at least min_tracker_gaussians of it traced there and more than
  // mask_visible_threshold of those in no kept mask): a missed frame says nothing about which
  // object a Gaussian belongs to. false = every traced frame counts.
  bool orphan_skips_missed_frames = true;
  int num_threads = 0;                 // 0 = all cores; results never depend on it
  const CancelFlag* cancel = nullptr;  // polled per view; not owned (common/core/cancel.h)

  absl::Status Validate() const;
};

}  // namespace instascene::decomposition
