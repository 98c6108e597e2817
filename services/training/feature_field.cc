#include "services/training/feature_field.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <numeric>
#include <random>

#include "absl/strings/str_cat.h"
#include "common/core/parallel.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/eval/result.h"
#include "common/raster/rasterizer.h"
#include "common/scene/image_io.h"
#include "services/training/contrastive_loss.h"

namespace instascene::training {
namespace {

constexpr double kRenderEps = 1e-9;  // f / (|f| + 1e-9) before splatting
constexpr double kThreeDEps = 1e-6;  // f / (|f| + 1e-6) for the 3D term

// v^T d(f / (|f| + eps))/df, added to out.
void AddNormalizationBackward(const float* f, const double* v, int dim, double eps, double* out) {
  double norm2 = 0, fv = 0;
  for (int d = 0; d < dim; ++d) {
    norm2 += double{f[d]} * f[d];
    fv += f[d] * v[d];
  }
  const double norm = std::sqrt(norm2), denom = norm + eps;
  const double coupling = norm > 0 ? fv / (norm * denom * denom) : 0.0;
  for (int d = 0; d < dim; ++d) out[d] += v[d] / denom - coupling * f[d];
}

void Normalize(const float* f, int dim, double eps, float* out) {
  double norm2 = 0;
  for (int d = 0; d < dim; ++d) norm2 += double{f[d]} * f[d];
  const double inv = 1.0 / (std::sqrt(norm2) + eps);
  for (int d = 0; d < dim; ++d) out[d] = static_cast<float>(f[d] * inv);
}

// Samples `count` indices with replacement from `candidates`.
std::vector<uint32_t> SampleWithReplacement(const std::vector<uint32_t>& candidates, int count,
                                            std::mt19937_64& rng) {
  std::vector<uint32_t> out;
  if (candidates.empty()) return out;
  std::uniform_int_distribution<size_t> pick(0, candidates.size() - 1);
  out.reserve(count);
  for (int i = 0; i < count; ++i) out.push_back(candidates[pick(rng)]);
  return out;
}

// A rendered-pixel term: samples (view, pool pixel) pairs, renders their features from the cached
// lists, applies the loss and scatters lambda * w * dL/dE into grad_hat (dL/df^).
double PixelTerm(const TrainingData& data, const std::vector<std::pair<int, uint32_t>>& samples,
                 const std::vector<uint32_t>& labels, const std::vector<float>& unit, int dim,
                 bool negatives, bool detach, double lambda, std::vector<double>* grad_hat) {
  if (samples.empty()) return 0.0;
  std::vector<float> x(samples.size() * dim, 0.0f);
  for (size_t j = 0; j < samples.size(); ++j) {
    const ViewData& v = data.views[samples[j].first];
    const uint32_t p = samples[j].second;
    for (uint64_t k = v.offsets[p]; k < v.offsets[p + 1]; ++k) {
      const float* f = &unit[static_cast<size_t>(v.gaussians[k]) * dim];
      for (int d = 0; d < dim; ++d) x[j * dim + d] += v.weights[k] * f[d];
    }
  }
  ContrastiveLossOptions loss_options;
  loss_options.consider_negative = negatives;
  loss_options.detach_norm = detach;
  std::vector<double> gx;
  const double loss = ContrastiveLoss(x, dim, labels, loss_options, &gx);
  for (size_t j = 0; j < samples.size(); ++j) {
    const ViewData& v = data.views[samples[j].first];
    const uint32_t p = samples[j].second;
    for (uint64_t k = v.offsets[p]; k < v.offsets[p + 1]; ++k) {
      double* g = &(*grad_hat)[static_cast<size_t>(v.gaussians[k]) * dim];
      for (int d = 0; d < dim; ++d) g[d] += lambda * v.weights[k] * gx[j * dim + d];
    }
  }
  return lambda * loss;
}

// One view's training data: a fixed pool of pixel_pool pixels (seeded per view), traced, with
// their raw, filtered and sorted labels, and the view's visible Gaussians with a coarse label.
absl::StatusOr<ViewData> PrepareView(const Scene& scene, const GaussianCloud& cloud, int v,
                                     const std::string& decomposition_dir,
                                     const std::vector<uint32_t>& labels3d,
                                     const TrainingOptions& options) {
  RETURN_IF_ERROR(CheckCancelled(options.cancel, "training preparation"));
  const SceneView& view = scene.views[v];
  ASSIGN_OR_RETURN(LabelMap raw, ReadViewMask(scene, v));
  const std::filesystem::path dir(decomposition_dir);
  ASSIGN_OR_RETURN(LabelMap filtered,
                   ReadLabelMap((dir / "masks_filtered" / (view.name + ".png")).string()));
  ASSIGN_OR_RETURN(LabelMap sorted,
                   ReadLabelMap((dir / "masks_sorted" / (view.name + ".png")).string()));
  const size_t pixels = static_cast<size_t>(view.camera.width) * view.camera.height;
  if (filtered.labels.size() != pixels || sorted.labels.size() != pixels) {
    return absl::InvalidArgumentError(
        absl::StrCat("decomposition maps of view '", view.name, "' do not match its camera"));
  }
  std::vector<uint32_t> all(pixels);
  std::iota(all.begin(), all.end(), 0u);
  std::vector<uint32_t> pool;
  std::mt19937_64 rng(options.seed * 7919 + static_cast<uint64_t>(v));
  std::sample(all.begin(), all.end(), std::back_inserter(pool), options.pixel_pool,
              rng);  // sorted output
  RenderOptions render;
  render.color = false;
  render.trace.enabled = true;
  render.trace.pixels = pool;
  ASSIGN_OR_RETURN(RenderResult r, Render(cloud, view.camera, render));
  ViewData out;
  out.offsets = r.trace.offsets;
  out.gaussians.reserve(r.trace.entries.size());
  out.weights.reserve(r.trace.entries.size());
  for (const Contribution& c : r.trace.entries) {
    out.gaussians.push_back(c.gaussian);
    out.weights.push_back(c.weight);
  }
  for (uint32_t p : pool) {
    out.raw_label.push_back(raw.labels[p]);
    // A removed (under-segmented) mask's pixels: left out, or the background class.
    const bool removed = raw.labels[p] > 0 && filtered.labels[p] == 0;
    out.filtered_label.push_back(removed && options.ignore_removed_masks ? kIgnoredLabel
                                                                         : filtered.labels[p]);
    out.sorted_label.push_back(sorted.labels[p]);
  }
  for (uint32_t g = 0; g < cloud.size(); ++g) {
    if (r.visible[g] && labels3d[g] > 0) out.visible_labelled.push_back(g);
  }
  return out;
}

}  // namespace

absl::StatusOr<TrainingData> PrepareTraining(const Scene& scene, const GaussianCloud& cloud,
                                             const std::string& decomposition_dir,
                                             const TrainingOptions& options,
                                             const std::function<void(int, int)>& progress) {
  RETURN_IF_ERROR(options.Validate());
  TrainingData data;
  data.num_gaussians = cloud.size();
  ASSIGN_OR_RETURN(
      data.labels3d,
      ReadGaussianInstanceIds((std::filesystem::path(decomposition_dir) / "labels.ply").string(),
                              cloud.size()));
  const int num_views = static_cast<int>(scene.views.size());
  data.views.resize(num_views);
  std::vector<absl::Status> status(num_views);
  int done = 0;
  std::mutex mutex;
  RunWithThreads(options.num_threads, [&] {
    tbb::parallel_for(0, num_views, [&](int v) {
      absl::StatusOr<ViewData> prepared =
          PrepareView(scene, cloud, v, decomposition_dir, data.labels3d, options);
      if (prepared.ok()) {
        data.views[v] = *std::move(prepared);
      } else {
        status[v] = prepared.status();
      }
      if (progress) {
        std::lock_guard<std::mutex> lock(mutex);
        progress(++done, num_views);
      }
    });
  });
  for (const absl::Status& s : status) RETURN_IF_ERROR(s);
  return data;
}

namespace {

// (a) single view: sampled pixels of `view` with their per-frame labels (raw or filtered masks).
double SingleViewTerm(const TrainingData& data, const TrainingOptions& options,
                      const std::vector<float>& unit, int view, std::mt19937_64& rng,
                      std::vector<double>* grad_hat) {
  const ViewData& v = data.views[view];
  const std::vector<uint32_t>& labels =
      options.supervision == Supervision::kNoisy2d ? v.raw_label : v.filtered_label;
  std::vector<uint32_t> valid;
  for (uint32_t p = 0; p < labels.size(); ++p) {
    if (labels[p] != kIgnoredLabel && (options.consider_negative || labels[p] > 0))
      valid.push_back(p);
  }
  std::vector<std::pair<int, uint32_t>> samples;
  std::vector<uint32_t> sample_labels;
  for (uint32_t p : SampleWithReplacement(valid, options.samples, rng)) {
    samples.emplace_back(view, p);
    sample_labels.push_back(labels[p]);
  }
  return PixelTerm(data, samples, sample_labels, unit, options.feature_dim,
                   options.consider_negative, options.detach_sample_norm, options.lambda_single,
                   grad_hat);
}

// (b) cross view: a window of consecutive views, pixels with a consistent instance id.
double CrossViewTerm(const TrainingData& data, const TrainingOptions& options,
                     const std::vector<float>& unit, std::mt19937_64& rng,
                     std::vector<double>* grad_hat) {
  const int num_views = static_cast<int>(data.views.size());
  const int window = std::min(options.multi_view_window, num_views);
  const int start =
      num_views > window ? std::uniform_int_distribution<int>(0, num_views - window - 1)(rng) : 0;
  std::vector<std::pair<int, uint32_t>> pool;
  for (int w = start; w < start + window; ++w) {
    for (uint32_t p = 0; p < data.views[w].sorted_label.size(); ++p) {
      if (data.views[w].sorted_label[p] > 0) pool.emplace_back(w, p);
    }
  }
  if (pool.empty()) return 0;
  std::uniform_int_distribution<size_t> pick(0, pool.size() - 1);
  std::vector<std::pair<int, uint32_t>> samples;
  std::vector<uint32_t> sample_labels;
  for (int i = 0; i < options.samples; ++i) {
    samples.push_back(pool[pick(rng)]);
    sample_labels.push_back(data.views[samples.back().first].sorted_label[samples.back().second]);
  }
  return PixelTerm(data, samples, sample_labels, unit, options.feature_dim, false,
                   options.detach_sample_norm, options.lambda_multi, grad_hat);
}

// (c) 3D: visible Gaussians of `view` with a coarse instance label; gradients straight into
// `grad` (through the 3D normalisation).
double ThreeDTerm(const TrainingData& data, const TrainingOptions& options,
                  const std::vector<float>& features, int view, std::mt19937_64& rng,
                  std::vector<double>* grad) {
  const int dim = options.feature_dim;
  const std::vector<uint32_t> picked =
      SampleWithReplacement(data.views[view].visible_labelled, options.samples, rng);
  if (picked.empty()) return 0;
  std::vector<float> x(picked.size() * dim);
  std::vector<uint32_t> labels(picked.size());
  for (size_t j = 0; j < picked.size(); ++j) {
    Normalize(&features[static_cast<size_t>(picked[j]) * dim], dim, kThreeDEps, &x[j * dim]);
    labels[j] = data.labels3d[picked[j]];
  }
  std::vector<double> gx;
  ContrastiveLossOptions loss_options;
  loss_options.detach_norm = options.detach_sample_norm;
  const double loss = options.lambda_3d * ContrastiveLoss(x, dim, labels, loss_options, &gx);
  for (size_t j = 0; j < picked.size(); ++j) {
    std::vector<double> scaled(dim);
    for (int d = 0; d < dim; ++d) scaled[d] = options.lambda_3d * gx[j * dim + d];
    AddNormalizationBackward(&features[static_cast<size_t>(picked[j]) * dim], scaled.data(), dim,
                             kThreeDEps, &(*grad)[static_cast<size_t>(picked[j]) * dim]);
  }
  return loss;
}

}  // namespace

double LossAndGradient(const TrainingData& data, const TrainingOptions& options,
                       const std::vector<float>& features, int view, bool with_multi_view,
                       uint64_t seed, std::vector<double>* grad) {
  const int dim = options.feature_dim;
  const size_t n = data.num_gaussians;
  std::mt19937_64 rng(seed);
  std::vector<float> unit(features.size());
  for (size_t g = 0; g < n; ++g) Normalize(&features[g * dim], dim, kRenderEps, &unit[g * dim]);
  std::vector<double> grad_hat(features.size(), 0.0);
  grad->assign(features.size(), 0.0);
  double loss = 0;
  if (options.supervision != Supervision::k3d) {
    loss += SingleViewTerm(data, options, unit, view, rng, &grad_hat);
  }
  if (options.supervision == Supervision::kFull && with_multi_view) {
    loss += CrossViewTerm(data, options, unit, rng, &grad_hat);
  }
  if (options.supervision != Supervision::kNoisy2d) {
    loss += ThreeDTerm(data, options, features, view, rng, grad);
  }
  // Back through the splatting normalisation.
  for (size_t g = 0; g < n; ++g) {
    const double* gh = &grad_hat[g * dim];
    bool any = false;
    for (int d = 0; d < dim && !any; ++d) any = gh[d] != 0.0;
    if (any) AddNormalizationBackward(&features[g * dim], gh, dim, kRenderEps, &(*grad)[g * dim]);
  }
  return loss;
}

absl::StatusOr<TrainingResult> TrainFeatures(
    const TrainingData& data, const TrainingOptions& options,
    const std::function<void(int, int, double)>& progress) {
  RETURN_IF_ERROR(options.Validate());
  if (data.views.empty()) return absl::InvalidArgumentError("no training views");
  const int dim = options.feature_dim;
  const size_t total = data.num_gaussians * dim;
  Stopwatch watch;
  TrainingResult result;
  result.features.resize(total);
  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  for (float& f : result.features) f = uni(rng);
  for (size_t g = 0; g < data.num_gaussians; ++g)
    Normalize(&result.features[g * dim], dim, 0.0, &result.features[g * dim]);
  std::vector<double> m(total, 0.0), v(total, 0.0), grad;
  std::vector<int> stack;  // shuffled views, refilled when empty
  constexpr double kBeta1 = 0.9, kBeta2 = 0.999, kEps = 1e-15;
  for (int step = 1; step <= options.iterations; ++step) {
    RETURN_IF_ERROR(CheckCancelled(options.cancel, "training"));
    if (stack.empty()) {
      stack.resize(data.views.size());
      std::iota(stack.begin(), stack.end(), 0);
      std::shuffle(stack.begin(), stack.end(), rng);
    }
    const int view = stack.back();
    stack.pop_back();
    const double loss = LossAndGradient(data, options, result.features, view,
                                        step % options.multi_view_every == 0, rng(), &grad);
    result.loss.push_back(loss);
    const double c1 = 1.0 - std::pow(kBeta1, step), c2 = 1.0 - std::pow(kBeta2, step);
    RunWithThreads(options.num_threads, [&] {
      tbb::parallel_for(
          tbb::blocked_range<size_t>(0, total, 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t i = r.begin(); i < r.end(); ++i) {
              m[i] = kBeta1 * m[i] + (1 - kBeta1) * grad[i];
              v[i] = kBeta2 * v[i] + (1 - kBeta2) * grad[i] * grad[i];
              result.features[i] -= static_cast<float>(options.learning_rate * (m[i] / c1) /
                                                       (std::sqrt(v[i] / c2) + kEps));
            }
          });
    });
    if (progress) progress(step, options.iterations, loss);
  }
  result.seconds = watch.ElapsedSeconds();
  return result;
}

}  // namespace instascene::training
