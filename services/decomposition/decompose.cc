#include "services/decomposition/decompose.h"

#include <filesystem>
#include <map>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/eval/result.h"
#include "common/scene/image_io.h"
#include "common/splat/ply.h"
#include "services/decomposition/instance_merging.h"
#include "services/decomposition/mask_holding.h"
#include "services/decomposition/unlabelled_gaussians.h"

namespace instascene::decomposition {

std::vector<uint32_t> DecompositionResult::Labels() const {
  return InstanceOf(instances, trackers.num_gaussians);
}

namespace {

// Stage B's trackers (4.1-4.2) from the scene's masks; each view must have one.
absl::StatusOr<TrackerSet> TrackScene(const Scene& scene, const GaussianCloud& cloud,
                                      const DecompositionOptions& options,
                                      const ProgressFn& progress) {
  std::vector<PinholeCamera> cameras;
  for (const SceneView& v : scene.views) {
    if (v.mask.empty())
      return absl::FailedPreconditionError(absl::StrCat("view '", v.name, "' has no mask"));
    cameras.push_back(v.camera);
  }
  MaskLoader loader = [&scene](int v) -> absl::StatusOr<std::vector<uint32_t>> {
    ASSIGN_OR_RETURN(LabelMap mask, ReadViewMask(scene, v));
    return std::vector<uint32_t>(mask.labels.begin(), mask.labels.end());
  };
  auto track_progress = [&](int done, int total) {
    if (progress) progress("tracking", done, total);
  };
  return BuildTrackers(cloud, cameras, loader, options, track_progress);
}

// Judgement, clustering and instances (4.3-4.7), re-judged against the instances found up to
// rejudge_passes times; the last clustering's nodes set result.cluster_of. Returns the seconds
// spent building instances (post-processing).
absl::StatusOr<double> ClusterAndRejudge(const GaussianCloud& cloud,
                                         const DecompositionOptions& options,
                                         const ProgressFn& progress, DecompositionResult* result) {
  const MaskJudgement judged = JudgeTrackers(result->trackers, options);
  result->judgement = judged;
  UndoUndersegmented(result->trackers, &result->judgement);
  if (progress) progress("clustering", 0, 1 + options.rejudge_passes);
  double post_seconds = 0;
  auto build_instances = [&](const std::vector<MaskNode>& nodes) {
    Stopwatch post;
    result->instances =
        BuildInstances(result->trackers, nodes, cloud, options, &result->judgement.undersegmented);
    post_seconds += post.ElapsedSeconds();
  };
  std::vector<MaskNode> nodes =
      ClusterMasks(result->trackers, result->judgement, options, &result->schedule);
  build_instances(nodes);
  std::vector<uint8_t> flags = judged.undersegmented;
  for (int pass = 0; pass < options.rejudge_passes; ++pass) {
    RETURN_IF_ERROR(CheckCancelled(options.cancel, "decompose"));
    if (RejudgeUndersegmented(result->trackers, result->instances, options, &flags,
                              &judged.frames) == 0)
      break;
    result->judgement = judged;
    result->judgement.undersegmented = flags;
    UndoUndersegmented(result->trackers, &result->judgement);
    nodes = ClusterMasks(result->trackers, result->judgement, options, &result->schedule);
    build_instances(nodes);
    if (progress) progress("clustering", pass + 2, 1 + options.rejudge_passes);
  }
  if (progress) progress("clustering", 1 + options.rejudge_passes, 1 + options.rejudge_passes);
  result->cluster_of.assign(result->trackers.trackers.size(), -1);
  for (size_t k = 0; k < nodes.size(); ++k) {
    for (uint32_t t : nodes[k].masks) result->cluster_of[t] = static_cast<int32_t>(k);
  }
  return post_seconds;
}

// After the clustering: unseparated instances merged, under-segmented masks remedied, orphan
// and untraced Gaussians labelled.
absl::Status PostProcess(const GaussianCloud& cloud, const DecompositionOptions& options,
                         DecompositionResult* result) {
  result->merged_instances =
      MergeUnseparatedInstances(result->trackers, options, &result->instances);
  result->undersegmented =
      RemedyUndersegmented(result->trackers, result->judgement, options, &result->instances);
  const float step = static_cast<float>(options.untraced_radius * RobustSceneDiagonal(cloud));
  result->orphans_labelled =
      LabelOrphanGaussians(result->trackers, cloud, step, options, &result->instances);
  RETURN_IF_ERROR(CheckCancelled(options.cancel, "decompose"));
  result->untraced_labelled = LabelUntracedGaussians(result->trackers, cloud, step,
                                                     options.num_threads, &result->instances);
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<DecompositionResult> Decompose(const Scene& scene, const GaussianCloud& cloud,
                                              const DecompositionOptions& options,
                                              const ProgressFn& progress) {
  RETURN_IF_ERROR(options.Validate());
  DecompositionResult result;
  Stopwatch watch;
  ASSIGN_OR_RETURN(result.trackers, TrackScene(scene, cloud, options, progress));
  result.tracking_seconds = watch.ElapsedSeconds();
  watch.Restart();
  // Instance building inside the re-judgement loop counts as post-processing.
  ASSIGN_OR_RETURN(const double post_seconds, ClusterAndRejudge(cloud, options, progress, &result));
  result.clustering_seconds = watch.ElapsedSeconds() - post_seconds;
  watch.Restart();
  RETURN_IF_ERROR(PostProcess(cloud, options, &result));
  result.post_seconds = post_seconds + watch.ElapsedSeconds();
  if (progress) progress("post-processing", 1, 1);
  return result;
}

namespace {
namespace fs = std::filesystem;

// (mask id, instance) per view, and the under-segmented masks' ids per view.
using SortedByView = std::vector<std::vector<std::pair<uint32_t, uint32_t>>>;
using MasksByView = std::vector<std::vector<uint32_t>>;

// Full 3D masks, overlaps included: one (instance, gaussian) row per membership.
absl::Status WriteMembership(const fs::path& dir, const DecompositionResult& result) {
  PlyColumns membership;
  membership.names = {"instance", "gaussian"};
  membership.types = {ScalarType::kUint32, ScalarType::kUint32};
  membership.columns.resize(2);
  for (size_t k = 0; k < result.instances.size(); ++k) {
    for (uint32_t g : result.instances[k].gaussians) {
      membership.columns[0].push_back(static_cast<float>(k + 1));
      membership.columns[1].push_back(static_cast<float>(g));
    }
  }
  membership.count = static_cast<int64_t>(membership.columns[0].size());
  return WriteFileAtomically((dir / "instances.ply").string(),
                             EncodePlyBinary("membership", membership));
}

// The instances with their masks (2D clusters); fills `sorted_by_view`.
nlohmann::json InstancesJson(const Scene& scene, const DecompositionResult& result,
                             SortedByView* sorted_by_view) {
  nlohmann::json instances = nlohmann::json::array();
  for (size_t k = 0; k < result.instances.size(); ++k) {
    const Instance& inst = result.instances[k];
    nlohmann::json masks = nlohmann::json::array();
    for (size_t i = 0; i < inst.masks.size(); ++i) {
      const Tracker& t = result.trackers.trackers[inst.masks[i]];
      masks.push_back({{"view", scene.views[t.view].name},
                       {"mask", t.mask_id},
                       {"coverage", inst.coverage[i]}});
      (*sorted_by_view)[t.view].emplace_back(t.mask_id, static_cast<uint32_t>(k + 1));
    }
    instances.push_back({{"id", k + 1}, {"gaussians", inst.gaussians.size()}, {"masks", masks}});
  }
  return instances;
}

// The under-segmented masks; fills `under_by_view`.
nlohmann::json UndersegmentedJson(const Scene& scene, const DecompositionResult& result,
                                  MasksByView* under_by_view) {
  nlohmann::json under = nlohmann::json::array();
  for (uint32_t u : result.undersegmented) {
    const Tracker& t = result.trackers.trackers[u];
    under.push_back({{"view", scene.views[t.view].name}, {"mask", t.mask_id}});
    (*under_by_view)[t.view].push_back(t.mask_id);
  }
  return under;
}

// Every kept mask (tracker) and what became of it.
nlohmann::json MaskFatesJson(const Scene& scene, const DecompositionResult& result) {
  const TrackerSet& set = result.trackers;
  std::vector<int64_t> instance_of_tracker(set.trackers.size(), 0);
  for (size_t k = 0; k < result.instances.size(); ++k) {
    for (uint32_t t : result.instances[k].masks)
      instance_of_tracker[t] = static_cast<int64_t>(k + 1);
  }
  std::map<int32_t, int> cluster_size;
  for (int32_t c : result.cluster_of) ++cluster_size[c];
  nlohmann::json masks = nlohmann::json::array();
  for (size_t t = 0; t < set.trackers.size(); ++t) {
    const Tracker& tracker = set.trackers[t];
    std::string fate;
    if (instance_of_tracker[t] > 0) {
      fate = "instance";
    } else if (result.judgement.undersegmented[t]) {
      fate = "undersegmented";
    } else if (t < result.cluster_of.size() && cluster_size[result.cluster_of[t]] < 2) {
      fate = "unclustered";  // its cluster holds only this mask
    } else {
      fate = "filtered";  // its cluster's sub-object kept < 2 masks, or was a contained duplicate
    }
    nlohmann::json entry = {{"view", scene.views[tracker.view].name},
                            {"mask", tracker.mask_id},
                            {"gaussians", tracker.gaussians.size()},
                            {"fate", fate},
                            {"instance", instance_of_tracker[t]}};
    if (t < result.cluster_of.size()) entry["cluster"] = result.cluster_of[t];
    masks.push_back(std::move(entry));
  }
  return masks;
}

// Per view: the filtered mask map (under-segmented masks removed) and the sorted one (global
// instance ids).
absl::Status WriteViewMaps(const fs::path& dir, const Scene& scene,
                           const SortedByView& sorted_by_view, const MasksByView& under_by_view) {
  for (size_t v = 0; v < scene.views.size(); ++v) {
    ASSIGN_OR_RETURN(LabelMap mask, ReadViewMask(scene, static_cast<int>(v)));
    // Per-view lookup tables over the 16-bit mask ids.
    std::vector<uint16_t> instance_of(65536, 0);
    std::vector<uint8_t> removed(65536, 0);
    for (const auto& [mask_id, instance] : sorted_by_view[v]) {  // later instances win
      if (mask_id < 65536)
        instance_of[mask_id] = static_cast<uint16_t>(std::min<uint32_t>(instance, 65535));
    }
    for (uint32_t mask_id : under_by_view[v]) {
      if (mask_id < 65536) removed[mask_id] = 1;
    }
    LabelMap filtered = mask,
             sorted{mask.width, mask.height, std::vector<uint16_t>(mask.labels.size(), 0)};
    for (size_t p = 0; p < mask.labels.size(); ++p) {
      if (removed[mask.labels[p]]) filtered.labels[p] = 0;
      sorted.labels[p] = instance_of[mask.labels[p]];
    }
    const std::string name = scene.views[v].name + ".png";
    RETURN_IF_ERROR(WriteLabelMap((dir / "masks_filtered" / name).string(), filtered));
    RETURN_IF_ERROR(WriteLabelMap((dir / "masks_sorted" / name).string(), sorted));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status WriteDecomposition(const std::string& directory, const Scene& scene,
                                const GaussianCloud& cloud, const DecompositionResult& result) {
  const fs::path dir(directory);
  std::error_code ec;
  for (const char* sub : {"masks_filtered", "masks_sorted"}) {
    fs::create_directories(dir / sub, ec);
    if (ec)
      return absl::UnavailableError(
          absl::StrCat((dir / sub).string(), ": cannot create: ", ec.message()));
  }
  // Evaluation result (one label per Gaussian).
  SegmentationResult labels;
  labels.stage = "decompose";
  labels.labels = result.Labels();
  RETURN_IF_ERROR(WriteResult(directory, labels, cloud));
  RETURN_IF_ERROR(WriteMembership(dir, result));
  SortedByView sorted_by_view(scene.views.size());
  MasksByView under_by_view(scene.views.size());
  const nlohmann::json summary = {
      {"format", "instascene.decomposition/1"},
      {"instances", InstancesJson(scene, result, &sorted_by_view)},
      {"undersegmented", UndersegmentedJson(scene, result, &under_by_view)},
      {"masks", MaskFatesJson(scene, result)},
      {"trackers", result.trackers.trackers.size()},
      {"observer_schedule", result.schedule},
      {"merged_instances", result.merged_instances},
      {"orphans_labelled", result.orphans_labelled},
      {"untraced_labelled", result.untraced_labelled},
      {"seconds",
       {{"tracking", result.tracking_seconds},
        {"clustering", result.clustering_seconds},
        {"post_processing", result.post_seconds}}}};
  RETURN_IF_ERROR(WriteFileAtomically((dir / "decomposition.json").string(), summary.dump(1)));
  return WriteViewMaps(dir, scene, sorted_by_view, under_by_view);
}

}  // namespace instascene::decomposition
