#include "common/eval/click_eval.h"

#include <algorithm>
#include <cmath>
#include <map>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/raster/label_render.h"
#include "common/raster/rasterizer.h"

namespace instascene {
namespace {

// What one view contributes: a predicted per-pixel map for each object selection.
struct ViewRender {
  std::vector<uint32_t> labels;  // label mode
  std::vector<float> features;   // feature mode: normalised per pixel, W*H*D
  std::vector<float> alpha;
};

std::vector<float> NormalizedRows(const std::vector<float>& values, int dim) {
  std::vector<float> out(values.size());
  for (size_t i = 0; i + dim <= values.size(); i += dim) {
    double norm = 0;
    for (int d = 0; d < dim; ++d) norm += double{values[i + d]} * values[i + d];
    const float inv = static_cast<float>(1.0 / (std::sqrt(norm) + 1e-9));
    for (int d = 0; d < dim; ++d) out[i + d] = values[i + d] * inv;
  }
  return out;
}

absl::StatusOr<ViewRender> RenderView(const GaussianCloud& cloud, const PinholeCamera& camera,
                                      const SegmentationResult& result,
                                      const std::vector<float>& unit_features, bool features,
                                      const ClickEvalOptions& options) {
  ViewRender view;
  if (features) {
    RenderOptions render;
    render.color = false;
    render.features =
        unit_features.data();  // splatted features are the normalised ones (ALGORITHM 5.1)
    render.feature_dim = result.feature_dim;
    render.num_threads = options.num_threads;
    ASSIGN_OR_RETURN(RenderResult r, Render(cloud, camera, render));
    view.features = NormalizedRows(r.features, result.feature_dim);
    view.alpha = std::move(r.alpha);
  } else {
    ASSIGN_OR_RETURN(view.labels, RenderLabelMap(cloud, camera, result.labels, options.min_alpha,
                                                 options.num_threads));
  }
  return view;
}

// The views where each object is visible (GT area >= min_visible_pixels) with its area there;
// never-visible objects present with no views (they score 0).
using VisibleViews = std::map<uint32_t, std::vector<std::pair<int, size_t>>>;
VisibleViews FindVisibleViews(const std::vector<std::vector<uint32_t>>& gt_masks,
                              const std::vector<uint32_t>& gt_ids, int min_visible_pixels) {
  VisibleViews visible;
  for (size_t v = 0; v < gt_masks.size(); ++v) {
    std::map<uint32_t, size_t> area;
    for (uint32_t id : gt_masks[v])
      if (id != 0) ++area[id];
    for (const auto& [id, a] : area) {
      if (a >= static_cast<size_t>(min_visible_pixels))
        visible[id].emplace_back(static_cast<int>(v), a);
    }
  }
  for (uint32_t id : gt_ids)
    if (id != 0) visible.try_emplace(id);
  return visible;
}

// Each object's score entry and reference view (where its GT mask is largest); returns the
// objects by reference view.
std::map<int, std::vector<uint32_t>> ReferenceViews(const VisibleViews& visible,
                                                    const std::vector<std::string>& names,
                                                    std::map<uint32_t, ObjectClickScore>* scores) {
  std::map<int, std::vector<uint32_t>> by_reference_view;
  for (const auto& [id, views] : visible) {
    ObjectClickScore& s = (*scores)[id];
    s.id = id;
    s.name = id < names.size() ? names[id] : absl::StrCat("object_", id);
    if (views.empty()) continue;
    s.reference_view =
        std::max_element(views.begin(), views.end(), [](const auto& a, const auto& b) {
          return a.second < b.second;
        })->first;
    by_reference_view[s.reference_view].push_back(id);
  }
  return by_reference_view;
}

// What a click on one object selects: a unit reference feature, or a label.
struct Selection {
  std::vector<float> feature;  // feature mode
  uint32_t label = 0;          // label mode
};

// The selection made in the reference view: the mean normalised rendered feature inside the GT
// mask, re-normalised, or the most frequent predicted label there.
Selection SelectInView(const ViewRender& view, const std::vector<uint32_t>& gt, uint32_t id,
                       bool features, int dim) {
  Selection selection;
  if (features) {
    std::vector<double> mean(dim, 0.0);
    for (size_t p = 0; p < gt.size(); ++p) {
      if (gt[p] != id) continue;
      for (int d = 0; d < dim; ++d) mean[d] += view.features[p * dim + d];
    }
    double norm = 0;
    for (double m : mean) norm += m * m;
    norm = std::sqrt(norm) + 1e-12;
    for (double m : mean) selection.feature.push_back(static_cast<float>(m / norm));
  } else {
    std::map<uint32_t, size_t> votes;
    for (size_t p = 0; p < gt.size(); ++p)
      if (gt[p] == id) ++votes[view.labels[p]];
    selection.label =
        std::max_element(votes.begin(), votes.end(), [](const auto& a, const auto& b) {
          return a.second < b.second;
        })->first;
  }
  return selection;
}

// IoU of the selected mask against the GT mask of object `id` in one view.
double SelectionIoU(const ViewRender& view, const std::vector<uint32_t>& gt, uint32_t id,
                    const Selection& selection, bool features, int dim,
                    const ClickEvalOptions& options) {
  size_t inter = 0, uni = 0;
  for (size_t p = 0; p < gt.size(); ++p) {
    bool selected;
    if (features) {
      double cos = 0;
      for (int d = 0; d < dim; ++d)
        cos += double{view.features[p * dim + d]} * selection.feature[d];
      selected = view.alpha[p] >= options.min_alpha && cos >= options.feature_threshold;
    } else {
      selected = selection.label != 0 && view.labels[p] == selection.label;
    }
    const bool truth = gt[p] == id;
    inter += selected && truth;
    uni += selected || truth;
  }
  return uni == 0 ? 0.0 : static_cast<double>(inter) / static_cast<double>(uni);
}

// 3D metrics over the Gaussians some view shows (blending weight above observed_min_weight).
absl::Status EvaluateObservedGaussians(const Scene& scene, const GaussianCloud& cloud,
                                       const std::vector<uint32_t>& gt_ids,
                                       const SegmentationResult& result,
                                       const ClickEvalOptions& options, ClickEvaluation* eval) {
  std::vector<uint8_t> observed(cloud.size(), 0);
  RenderOptions trace_options;
  trace_options.color = false;
  trace_options.trace.enabled = true;
  trace_options.trace.min_weight = options.observed_min_weight;
  trace_options.num_threads = options.num_threads;
  RasterWorkspace workspace;
  trace_options.workspace = &workspace;
  RenderResult traced;
  for (const SceneView& v : scene.views) {
    RETURN_IF_ERROR(RenderInto(cloud, v.camera, trace_options, &traced));
    for (const Contribution& c : traced.trace.entries) observed[c.gaussian] = 1;
  }
  std::vector<uint32_t> pred_observed, gt_observed;
  for (size_t g = 0; g < cloud.size(); ++g) {
    if (!observed[g]) continue;
    pred_observed.push_back(result.labels[g]);
    gt_observed.push_back(gt_ids[g]);
  }
  eval->observed_gaussians = pred_observed.size();
  eval->instances = MatchInstances(pred_observed, gt_observed);
  eval->adjusted_rand_index = AdjustedRandIndex(pred_observed, gt_observed);
  return absl::OkStatus();
}

absl::Status CheckClickInputs(const Scene& scene, const GaussianCloud& cloud,
                              const std::vector<std::vector<uint32_t>>& gt_masks,
                              const std::vector<uint32_t>& gt_ids,
                              const SegmentationResult& result) {
  if (gt_masks.size() != scene.views.size())
    return absl::InvalidArgumentError("one GT mask per view is required");
  if (result.labels.size() != cloud.size() || gt_ids.size() != cloud.size()) {
    return absl::InvalidArgumentError(
        "labels, GT ids and the cloud disagree on the Gaussian count");
  }
  return absl::OkStatus();
}

// Per object the mean IoU over the views it is visible in; the scene's mIoU is the mean over
// objects (Gaussian Grouping's averaging).
void AverageObjects(std::map<uint32_t, Selection>& selections, std::map<uint32_t, double>& iou_sum,
                    std::map<uint32_t, ObjectClickScore>* scores, ClickEvaluation* eval) {
  double total = 0;
  for (auto& [id, s] : *scores) {
    s.selected_label = selections[id].label;
    s.miou = s.views > 0 ? iou_sum[id] / s.views : 0.0;
    total += s.miou;
    eval->objects.push_back(s);
  }
  eval->miou = eval->objects.empty() ? 0.0 : total / static_cast<double>(eval->objects.size());
}

}  // namespace

absl::StatusOr<ClickEvaluation> EvaluateClicks(const Scene& scene, const GaussianCloud& cloud,
                                               const std::vector<std::vector<uint32_t>>& gt_masks,
                                               const std::vector<uint32_t>& gt_ids,
                                               const SegmentationResult& result,
                                               const std::vector<std::string>& names,
                                               const ClickEvalOptions& options) {
  RETURN_IF_ERROR(CheckClickInputs(scene, cloud, gt_masks, gt_ids, result));
  ClickEvaluation eval;
  eval.used_features = options.use_features && result.feature_dim > 0;
  const bool features = eval.used_features;
  const int dim = result.feature_dim;
  const std::vector<float> unit_features =
      features ? NormalizedRows(result.features, dim) : std::vector<float>{};
  auto render = [&](int v) {
    return RenderView(cloud, scene.views[v].camera, result, unit_features, features, options);
  };
  const VisibleViews visible = FindVisibleViews(gt_masks, gt_ids, options.min_visible_pixels);
  std::map<uint32_t, ObjectClickScore> scores;
  const std::map<int, std::vector<uint32_t>> by_reference_view =
      ReferenceViews(visible, names, &scores);
  // Pass 1: the selection made in each reference view.
  std::map<uint32_t, Selection> selections;
  for (const auto& [v, ids] : by_reference_view) {
    ASSIGN_OR_RETURN(ViewRender view, render(v));
    for (uint32_t id : ids) selections[id] = SelectInView(view, gt_masks[v], id, features, dim);
  }
  // Pass 2: IoU in every view where each object is visible.
  std::map<int, std::vector<uint32_t>> objects_in_view;
  for (const auto& [id, views] : visible)
    for (const auto& [v, a] : views) objects_in_view[v].push_back(id);
  std::map<uint32_t, double> iou_sum;
  for (const auto& [v, ids] : objects_in_view) {
    ASSIGN_OR_RETURN(ViewRender view, render(v));
    for (uint32_t id : ids) {
      iou_sum[id] += SelectionIoU(view, gt_masks[v], id, selections[id], features, dim, options);
      ++scores[id].views;
    }
  }
  AverageObjects(selections, iou_sum, &scores, &eval);
  RETURN_IF_ERROR(EvaluateObservedGaussians(scene, cloud, gt_ids, result, options, &eval));
  return eval;
}

absl::StatusOr<ClickEvaluation> EvaluateResultDirectory(const std::string& scene_dir,
                                                        const std::string& result_dir,
                                                        const ClickEvalOptions& options) {
  ASSIGN_OR_RETURN(Scene scene, ReadScene(scene_dir));
  if (!scene.metadata.contains("gt") || !scene.metadata["gt"].is_object()) {
    return absl::FailedPreconditionError(
        absl::StrCat(scene_dir, ": scene has no ground truth (\"gt\" in scene.json)"));
  }
  const nlohmann::json& gt = scene.metadata["gt"];
  ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
  ASSIGN_OR_RETURN(
      std::vector<uint32_t> gt_ids,
      ReadGaussianInstanceIds(
          scene.Path(gt.value("gaussian_instances", std::string("gt/labels.ply"))), cloud.size()));
  ASSIGN_OR_RETURN(SegmentationResult result, ReadResult(result_dir, cloud.size()));
  std::vector<std::vector<uint32_t>> masks;
  const std::string mask_dir = gt.value("masks", std::string("gt/masks"));
  for (const SceneView& v : scene.views) {
    ASSIGN_OR_RETURN(LabelMap m,
                     ReadLabelMap(scene.Path(absl::StrCat(mask_dir, "/", v.name, ".png"))));
    if (m.width != v.camera.width || m.height != v.camera.height) {
      return absl::InvalidArgumentError(
          absl::StrCat("GT mask of view '", v.name, "' does not match its camera size"));
    }
    masks.emplace_back(m.labels.begin(), m.labels.end());
  }
  std::vector<std::string> names;
  if (gt.contains("objects")) {
    ASSIGN_OR_RETURN(std::string text, ReadFileBounded(scene.Path(gt["objects"].get<std::string>()),
                                                       size_t{64} << 20));
    nlohmann::json objects = nlohmann::json::parse(text, nullptr, false);
    if (objects.is_array()) {
      for (const auto& o : objects) {
        const uint32_t id = o.value("id", 0u);
        if (id >= names.size()) names.resize(id + 1);
        names[id] = o.value("name", std::string());
      }
    }
  }
  return EvaluateClicks(scene, cloud, masks, gt_ids, result, names, options);
}

}  // namespace instascene
