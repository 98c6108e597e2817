#include "services/training/segmentation.h"

#include <cmath>
#include <filesystem>
#include <map>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/geometry/point_index.h"
#include "common/splat/gaussian_ply.h"
#include "common/splat/ply.h"
#include "services/training/density_labels.h"

namespace instascene::training {
namespace {

constexpr uint32_t kNone = 0xffffffffu;

// The keep step's candidates: Gaussians of a coarse instance left unlabelled, each with the
// neighbours it needs carrying its instance (half, or with its feature below keep_min_dot,
// keep_surrounded of them).
struct KeepCandidates {
  std::vector<uint32_t> gaussians, index_of;  // index_of: per Gaussian, its candidate or kNone
  std::vector<size_t> need;
};

KeepCandidates FindCandidates(const std::vector<uint32_t>& coarse,
                              const std::vector<double>& own_dot, const SegmentOptions& options,
                              const std::vector<uint32_t>& labels) {
  const size_t k = static_cast<size_t>(options.keep_neighbours);
  const size_t surrounded =
      static_cast<size_t>(std::ceil(options.keep_surrounded * static_cast<double>(k) - 1e-9));
  KeepCandidates c;
  c.index_of.assign(coarse.size(), kNone);
  for (uint32_t g = 0; g < coarse.size(); ++g) {
    if (labels[g] != 0 || coarse[g] == 0) continue;
    if (own_dot[g] >= options.keep_min_dot) {
      c.need.push_back((k + 1) / 2);
    } else if (surrounded <= k) {
      c.need.push_back(surrounded);
    } else {
      continue;
    }
    c.index_of[g] = static_cast<uint32_t>(c.gaussians.size());
    c.gaussians.push_back(g);
  }
  return c;
}

// SegmentOptions' keep step. Candidates: Gaussians of a coarse instance left unlabelled whose
// feature matches their own instance's mean at least keep_min_dot. In rounds, a candidate is kept
// once at least half its nearest Gaussians carry its instance in the labels the previous round
// left (each round decided on the same labels: the result does not depend on the order). Each
// candidate counts its neighbours carrying its instance; a kept one raises the counts of the
// candidates it neighbours, so the whole step costs O(candidates x neighbours), however many
// rounds a chain of candidates takes.
void KeepUnclaimed(const std::vector<uint32_t>& coarse, const std::vector<double>& own_dot,
                   const std::vector<float>& positions, const SegmentOptions& options,
                   std::vector<uint32_t>* labels) {
  const KeepCandidates c = FindCandidates(coarse, own_dot, options, *labels);
  if (c.gaussians.empty()) return;
  const size_t n = coarse.size(), k = static_cast<size_t>(options.keep_neighbours);
  std::vector<Eigen::Vector3f> points(n);
  for (size_t g = 0; g < n; ++g) points[g] = Eigen::Vector3f(&positions[3 * g]);
  const PointIndex3 index(std::move(points));
  std::vector<size_t> carrying(c.gaussians.size(), 0);
  std::vector<std::vector<uint32_t>> watchers(c.gaussians.size());  // candidates neighbouring one
  for (uint32_t i = 0; i < c.gaussians.size(); ++i) {
    const uint32_t g = c.gaussians[i];
    size_t taken = 0;
    for (const auto& match : index.KNearest(index.points()[g], k + 1)) {
      if (match.first == g || taken == k) continue;
      ++taken;
      carrying[i] += (*labels)[match.first] == coarse[g];
      if (c.index_of[match.first] != kNone) watchers[c.index_of[match.first]].push_back(i);
    }
  }
  std::vector<uint8_t> queued(c.gaussians.size(), 0);
  std::vector<uint32_t> round;
  for (uint32_t i = 0; i < c.gaussians.size(); ++i) {
    if (carrying[i] >= c.need[i]) {
      round.push_back(i);
      queued[i] = 1;
    }
  }
  while (!round.empty()) {
    for (uint32_t i : round) (*labels)[c.gaussians[i]] = coarse[c.gaussians[i]];
    std::vector<uint32_t> next;
    for (uint32_t i : round) {
      for (uint32_t j : watchers[i]) {
        if (queued[j] || coarse[c.gaussians[j]] != coarse[c.gaussians[i]]) continue;
        if (++carrying[j] >= c.need[j]) {
          next.push_back(j);
          queued[j] = 1;
        }
      }
    }
    round.swap(next);
  }
}

// Each coarse instance's mean unit feature (not re-normalised) and its Gaussian count.
void InstanceMeans(const std::vector<double>& unit, int dim, const std::vector<uint32_t>& coarse,
                   std::map<uint32_t, std::vector<double>>* mean,
                   std::map<uint32_t, double>* count) {
  for (size_t g = 0; g < coarse.size(); ++g) {
    if (coarse[g] == 0) continue;
    std::vector<double>& m = (*mean)[coarse[g]];
    m.resize(dim, 0.0);
    for (int d = 0; d < dim; ++d) m[d] += unit[g * dim + d];
    (*count)[coarse[g]] += 1;
  }
  for (auto& [id, m] : *mean) {
    for (double& v : m) v /= (*count)[id];
  }
}

// Instances that select (almost) nothing, or far more than their coarse mask, keep that mask;
// what such an instance selected outside its coarse mask returns to its own coarse label.
void FallBackToCoarse(const std::vector<uint32_t>& coarse, const std::map<uint32_t, double>& count,
                      const SegmentOptions& options, std::vector<uint32_t>* labels) {
  std::map<uint32_t, size_t> selected;
  for (uint32_t label : *labels) {
    if (label != 0) ++selected[label];
  }
  std::map<uint32_t, bool> fallback;
  for (const auto& [id, c] : count) {
    fallback[id] = selected[id] == 0 || selected[id] < options.min_kept_share * c ||
                   (options.max_growth > 0 && selected[id] > options.max_growth * c);
  }
  for (size_t g = 0; g < coarse.size(); ++g) {
    uint32_t& label = (*labels)[g];
    if (label != 0 && fallback[label] && label != coarse[g]) label = coarse[g];
    if (coarse[g] != 0 && fallback[coarse[g]]) label = coarse[g];
  }
}

}  // namespace

std::vector<uint32_t> SegmentByFeatures(const std::vector<float>& features, int dim,
                                        const std::vector<uint32_t>& coarse,
                                        const std::vector<float>& positions,
                                        const SegmentOptions& options) {
  const size_t n = coarse.size();
  std::vector<double> unit(features.size());
  for (size_t g = 0; g < n; ++g) {
    double norm = 0;
    for (int d = 0; d < dim; ++d) norm += double{features[g * dim + d]} * features[g * dim + d];
    for (int d = 0; d < dim; ++d)
      unit[g * dim + d] = features[g * dim + d] / (std::sqrt(norm) + 1e-6);
  }
  std::map<uint32_t, std::vector<double>> mean;
  std::map<uint32_t, double> count;
  InstanceMeans(unit, dim, coarse, &mean, &count);
  std::vector<uint32_t> labels(n, 0);
  std::vector<double> own_dot(n, -1e30);  // with the Gaussian's own coarse instance's mean
  for (size_t g = 0; g < n; ++g) {
    double best = -1e30;
    uint32_t best_id = 0;
    for (const auto& [id, m] : mean) {
      double dot = 0;
      for (int d = 0; d < dim; ++d) dot += m[d] * unit[g * dim + d];
      if (dot > best) {
        best = dot;
        best_id = id;
      }
      if (id == coarse[g]) own_dot[g] = dot;
    }
    if (best >= options.threshold) labels[g] = best_id;
  }
  if (options.keep_neighbours > 0 && positions.size() == 3 * n)
    KeepUnclaimed(coarse, own_dot, positions, options, &labels);
  FallBackToCoarse(coarse, count, options, &labels);
  return labels;
}

SegmentationResult TrainedResult(const TrainingResult& trained, const TrainingData& data,
                                 const GaussianCloud& cloud, int dim,
                                 const SegmentOptions& options) {
  SegmentationResult result;
  result.stage = "segment";
  result.labels = SegmentByFeatures(trained.features, dim, data.labels3d, cloud.positions, options);
  result.features = trained.features;
  result.feature_dim = dim;
  return result;
}

absl::StatusOr<std::vector<uint32_t>> FinalLabels(const SegmentationResult& trained,
                                                  const GaussianCloud& cloud,
                                                  const SegmentStageOptions& options,
                                                  int num_threads, nlohmann::json* metadata) {
  (*metadata)["labelling"] = options.labelling;
  if (trained.feature_dim == 0) return trained.labels;  // e.g. the vote baseline: nothing to do
  if (options.labelling == "tau") {
    (*metadata)["threshold"] = options.threshold;
    (*metadata)["min_kept_share"] = options.min_kept_share;
    (*metadata)["max_growth"] = options.max_growth;
    (*metadata)["keep_min_dot"] = options.keep_min_dot;
    (*metadata)["keep_neighbours"] = options.keep_neighbours;
    (*metadata)["keep_surrounded"] = options.keep_surrounded;
    return SegmentByFeatures(
        trained.features, trained.feature_dim, trained.labels, cloud.positions,
        SegmentOptions{options.threshold, options.min_kept_share, options.max_growth,
                       options.keep_min_dot, options.keep_neighbours, options.keep_surrounded});
  }
  DensityLabelOptions o;
  o.hdbscan.min_samples = options.min_samples;
  o.hdbscan.min_cluster_size = options.min_cluster_size;
  o.hdbscan.cluster_selection_epsilon = options.cluster_selection_epsilon;
  o.hdbscan.num_threads = num_threads;
  o.voxel = options.voxel;
  o.max_points = options.max_points;
  ASSIGN_OR_RETURN(DensityLabels labels,
                   LabelByDensity(cloud, trained.features, trained.feature_dim, o));
  const size_t returned =
      ReturnCoarseBackground(trained.labels, options.coarse_background_share, &labels.labels);
  (*metadata)["hdbscan"] = {{"clusters", labels.clusters},
                            {"points", labels.clustered_points},
                            {"voxel", labels.voxel},
                            {"coarse_background_share", options.coarse_background_share},
                            {"coarse_background_returned", returned}};
  return labels.labels;
}

absl::Status ExportInstances(const std::string& directory, const GaussianCloud& cloud,
                             const std::vector<uint32_t>& labels) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(fs::path(directory) / "instances", ec);
  if (ec) return absl::UnavailableError(absl::StrCat(directory, ": cannot create: ", ec.message()));
  std::map<uint32_t, std::vector<uint32_t>> members;
  for (uint32_t g = 0; g < labels.size(); ++g) {
    if (labels[g] != 0) members[labels[g]].push_back(g);
  }
  nlohmann::json manifest = nlohmann::json::array();
  for (const auto& [id, indices] : members) {
    const GaussianCloud instance = cloud.Subset(indices);
    const std::string file = absl::StrCat("instances/", id, ".ply");
    RETURN_IF_ERROR(WriteGaussianPly((fs::path(directory) / file).string(), instance));
    Eigen::AlignedBox3f box;
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (uint32_t g : indices) {
      const Eigen::Vector3f p(&cloud.positions[3 * g]);
      box.extend(p);
      centroid += p.cast<double>();
    }
    centroid /= static_cast<double>(indices.size());
    manifest.push_back({{"id", id},
                        {"gaussians", indices.size()},
                        {"ply", file},
                        {"bounds_min", {box.min().x(), box.min().y(), box.min().z()}},
                        {"bounds_max", {box.max().x(), box.max().y(), box.max().z()}},
                        {"centroid", {centroid.x(), centroid.y(), centroid.z()}}});
  }
  // The rest of the scene (label 0) as its own splat, so that a viewer can show the background and
  // every object as separate splats.
  std::vector<uint32_t> background;
  for (uint32_t g = 0; g < labels.size(); ++g) {
    if (labels[g] == 0) background.push_back(g);
  }
  if (!background.empty())
    RETURN_IF_ERROR(WriteGaussianPly(
        (fs::path(directory) / "instances" / "background.ply").string(), cloud.Subset(background)));
  GaussianCloud labelled = cloud;
  labelled.SetExtra("instance_id", ScalarType::kUint32,
                    std::vector<float>(labels.begin(), labels.end()));
  RETURN_IF_ERROR(
      WriteGaussianPly((fs::path(directory) / "scene_labelled.ply").string(), labelled));
  return WriteFileAtomically((fs::path(directory) / "instances.json").string(), manifest.dump(1));
}

}  // namespace instascene::training
