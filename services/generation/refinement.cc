#include "services/generation/refinement.h"

#include <chrono>
#include <cmath>
#include <random>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/raster/rasterizer.h"
#include "common/raster/tile_backward.h"
#include "services/generation/image_losses.h"
#include "services/generation/normal_consistency.h"

namespace instascene::generation {
namespace {

// The real views' normal-consistency term needs the median depth and the normals.
bool WantsNormals(const RefinementView& view, const RefinementOptions& options) {
  return !view.generated && options.lambda_normal > 0;
}

RenderOptions ViewOptions(const RefinementView& view, const RefinementOptions& options,
                          RasterWorkspace* ws) {
  RenderOptions o;
  for (float& b : o.background) b = 1.0f;
  o.depth = o.normal = WantsNormals(view, options);
  o.near_plane = view.near_plane;
  o.num_threads = options.num_threads;
  o.workspace = ws;
  return o;
}

// The object followed by the view's frozen context (core attributes only).
const GaussianCloud& WithContext(const GaussianCloud& object, const RefinementView& view,
                                 GaussianCloud* scratch) {
  if (view.context.size() == 0) return object;
  GaussianCloud& out = *scratch;
  out.num_scales = 2;
  out.sh_degree = object.sh_degree;
  out.extras.clear();
  auto join = [](const std::vector<float>& a, const std::vector<float>& b, std::vector<float>* o) {
    o->assign(a.begin(), a.end());
    o->insert(o->end(), b.begin(), b.end());
  };
  join(object.positions, view.context.positions, &out.positions);
  join(object.log_scales, view.context.log_scales, &out.log_scales);
  join(object.rotations, view.context.rotations, &out.rotations);
  join(object.opacity_logits, view.context.opacity_logits, &out.opacity_logits);
  join(object.sh, view.context.sh, &out.sh);
  return out;
}

// dL/d of the rendered images, zeroed and of the render's size (normal / median depth only
// when the view wants them).
struct ViewGradients {
  std::vector<float> color, alpha, normal, median_depth;
  explicit ViewGradients(const RenderResult& r)
      : color(r.color.size(), 0.0f),
        alpha(r.alpha.size(), 0.0f),
        normal(r.normal.size(), 0.0f),
        median_depth(r.median_depth.size(), 0.0f) {}
  ImageAdjoints Adjoints() const { return {color, alpha, normal, median_depth}; }
};

// The view's loss at `render`; its gradient is added into `grad`.
absl::StatusOr<double> ViewLoss(const RefinementView& view, const RenderResult& render,
                                const RefinementOptions& options, ViewGradients* grad) {
  if (!view.generated) {
    double loss = MaskedL1(render.color, view.rgb, view.mask, 1.0, &grad->color);
    if (WantsNormals(view, options)) {
      ASSIGN_OR_RETURN(const double normal,
                       NormalConsistency(render.normal, render.median_depth, render.alpha,
                                         view.mask, view.camera, options.lambda_normal,
                                         &grad->normal, &grad->median_depth));
      loss += options.lambda_normal * normal;
    }
    return loss;
  }
  const double l1 = MaskedL1(render.color, view.rgb, {}, 1.0 - options.lambda_dssim, &grad->color);
  const double dssim = Dssim(render.color, view.rgb, render.width, render.height,
                             options.lambda_dssim, &grad->color);
  const double bce = AlphaBce(render.alpha, view.mask, options.lambda_mask, &grad->alpha);
  return (1.0 - options.lambda_dssim) * l1 + options.lambda_dssim * dssim +
         options.lambda_mask * bce;
}

// Mean loss over every view (no gradients kept).
absl::StatusOr<double> MeanLoss(const GaussianCloud& cloud,
                                const std::vector<RefinementView>& views,
                                const RefinementOptions& options, RasterWorkspace* ws) {
  double sum = 0;
  GaussianCloud scratch;
  for (const RefinementView& view : views) {
    ASSIGN_OR_RETURN(RenderResult r, Render(WithContext(cloud, view, &scratch), view.camera,
                                            ViewOptions(view, options, ws)));
    ViewGradients unused(r);
    ASSIGN_OR_RETURN(const double loss, ViewLoss(view, r, options, &unused));
    sum += loss;
  }
  return views.empty() ? 0.0 : sum / views.size();
}

// Adam over one parameter array (beta 0.9 / 0.999, eps 1e-15, as the 3DGS / 2DGS optimisers).
struct Adam {
  std::vector<double> m, v;
  // lr_every[i % period] is parameter i's learning rate.
  void Step(std::vector<float>* params, const std::vector<float>& grad, int t,
            const std::vector<double>& lr_every) {
    if (m.empty()) {
      m.assign(params->size(), 0.0);
      v.assign(params->size(), 0.0);
    }
    const double b1 = 0.9, b2 = 0.999, eps = 1e-15;
    const double c1 = 1.0 - std::pow(b1, t), c2 = 1.0 - std::pow(b2, t);
    const size_t period = lr_every.size();
    float* p = params->data();
    for (size_t i = 0, k = 0; i < params->size(); ++i, k = k + 1 == period ? 0 : k + 1) {
      const double g = grad[i];
      m[i] = b1 * m[i] + (1 - b1) * g;
      v[i] = b2 * v[i] + (1 - b2) * g * g;
      p[i] = static_cast<float>(p[i] - lr_every[k] * (m[i] / c1) / (std::sqrt(v[i] / c2) + eps));
    }
  }
};

absl::Status CheckViews(const std::vector<RefinementView>& views, int sh_degree) {
  for (size_t k = 0; k < views.size(); ++k) {
    const RefinementView& v = views[k];
    RETURN_IF_ERROR(v.camera.Validate());
    const size_t pixels = static_cast<size_t>(v.camera.width) * v.camera.height;
    if (v.rgb.size() != 3 * pixels || v.mask.size() != pixels) {
      return absl::InvalidArgumentError(
          absl::StrCat("refinement view ", k, ": image or mask does not match its ", v.camera.width,
                       "x", v.camera.height, " camera"));
    }
    if (v.context.size() > 0 && (v.context.num_scales != 2 || v.context.sh_degree != sh_degree)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "refinement view ", k, ": its context is not 2DGS of the object's SH degree"));
    }
    if (!(v.near_plane > 0)) {
      return absl::InvalidArgumentError(absl::StrCat("refinement view ", k, ": near plane <= 0"));
    }
  }
  return absl::OkStatus();
}

// One view's loss and the object's gradients (the frozen context's dropped).
absl::StatusOr<double> ViewStep(const GaussianCloud& work, const RefinementView& view,
                                const RefinementOptions& options, RasterWorkspace* ws,
                                GaussianCloud* scratch, SurfelGradients* grad) {
  const RenderOptions ro = ViewOptions(view, options, ws);
  const GaussianCloud& scene = WithContext(work, view, scratch);
  ASSIGN_OR_RETURN(RenderResult render, RenderForBackward(scene, view.camera, ro));
  ViewGradients image_grad(render);
  ASSIGN_OR_RETURN(const double loss, ViewLoss(view, render, options, &image_grad));
  ASSIGN_OR_RETURN(*grad, TileBackward(scene, view.camera, ro, render, image_grad.Adjoints()));
  if (view.context.size() > 0) {  // the context is frozen: keep the object's gradients
    const size_t n = work.size();
    grad->positions.resize(3 * n);
    grad->log_scales.resize(2 * n);
    grad->rotations.resize(4 * n);
    grad->opacity_logits.resize(n);
    grad->sh.resize(static_cast<size_t>(work.sh_stride()) * n);
  }
  return loss;
}

// Adam per parameter group, with 2DGS's learning rates (the position's on its exponential
// schedule, no delay; the SH's DC and rest rates per value).
class Optimizer {
 public:
  Optimizer(const RefinementOptions& options, int sh_stride)
      : options_(options), sh_lr_(sh_stride, options.sh_rest_lr) {
    for (int k = 0; k < 3; ++k) sh_lr_[k] = options.sh_dc_lr;
  }
  void Step(const SurfelGradients& grad, int it, GaussianCloud* work) {
    const RefinementOptions& o = options_;
    const double t = o.iterations > 1 ? (it - 1.0) / (o.iterations - 1.0) : 0.0;
    const double pos_lr = o.spatial_scale * std::exp(std::log(o.position_lr_init) * (1 - t) +
                                                     std::log(o.position_lr_final) * t);
    pos_.Step(&work->positions, grad.positions, it, {pos_lr});
    scale_.Step(&work->log_scales, grad.log_scales, it, {o.scaling_lr});
    rot_.Step(&work->rotations, grad.rotations, it, {o.rotation_lr});
    opacity_.Step(&work->opacity_logits, grad.opacity_logits, it, {o.opacity_lr});
    sh_.Step(&work->sh, grad.sh, it, sh_lr_);
  }

 private:
  const RefinementOptions& options_;
  std::vector<double> sh_lr_;
  Adam pos_, scale_, rot_, opacity_, sh_;
};

absl::Status CheckRefinementOptions(const GaussianCloud& cloud, const RefinementOptions& options) {
  if (cloud.num_scales != 2) return absl::InvalidArgumentError("refinement needs 2DGS surfels");
  if (options.iterations < 0 || options.fixed_view_every < 1 || options.curve_every < 1 ||
      !(options.spatial_scale > 0) || !(options.lambda_normal >= 0)) {
    return absl::InvalidArgumentError(
        "refinement: needs iterations >= 0, fixed_view_every >= 1, curve_every >= 1, "
        "spatial_scale > 0, lambda_normal >= 0");
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<RefinementReport> RefineGaussians(GaussianCloud* cloud,
                                                 const std::vector<RefinementView>& views,
                                                 const RefinementOptions& options,
                                                 const RefinementProgress& progress) {
  RETURN_IF_ERROR(CheckRefinementOptions(*cloud, options));
  RETURN_IF_ERROR(CheckViews(views, cloud->sh_degree));
  const auto start = std::chrono::steady_clock::now();
  RefinementReport report;
  for (const RefinementView& v : views)
    (v.generated ? report.generated_views : report.real_views)++;
  RasterWorkspace ws;
  ASSIGN_OR_RETURN(report.initial_loss, MeanLoss(*cloud, views, options, &ws));
  report.final_loss = report.initial_loss;
  if (views.empty() || options.iterations == 0 || cloud->size() == 0) return report;

  GaussianCloud work = *cloud;  // the caller's cloud changes only on success
  Optimizer optimizer(options, work.sh_stride());
  std::mt19937_64 rng(options.seed);
  std::uniform_int_distribution<size_t> pick(0, views.size() - 1);
  double curve_sum = 0;
  int curve_count = 0;
  GaussianCloud scratch;
  for (int it = 1; it <= options.iterations; ++it) {
    RETURN_IF_ERROR(CheckCancelled(options.cancel, "refinement"));
    const size_t chosen = pick(rng);
    const size_t k = it % options.fixed_view_every == 0 ? 0 : chosen;
    SurfelGradients grad;
    ASSIGN_OR_RETURN(const double loss, ViewStep(work, views[k], options, &ws, &scratch, &grad));
    optimizer.Step(grad, it, &work);
    curve_sum += loss;
    if (++curve_count == options.curve_every || it == options.iterations) {
      report.loss_curve.push_back(curve_sum / curve_count);
      curve_sum = 0;
      curve_count = 0;
    }
    if (progress && (it % 50 == 0 || it == options.iterations))
      progress(it, options.iterations, loss);
  }
  report.iterations = options.iterations;
  ASSIGN_OR_RETURN(report.final_loss, MeanLoss(work, views, options, &ws));
  *cloud = std::move(work);
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

}  // namespace instascene::generation
