#include "services/generation/refinement_views.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/raster/rasterizer.h"
#include "services/generation/object_mesh.h"

namespace instascene::generation {
namespace {

float NearPlane(const PinholeCamera& camera, const ObjectFrame& frame) {
  const float distance = (camera.CenterInWorld().cast<float>() - frame.center).norm();
  return std::max(1e-6f, 0.01f * distance);
}

bool SameCamera(const PinholeCamera& a, const PinholeCamera& b) {
  return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy &&
         a.cx == b.cx && a.cy == b.cy &&
         a.camera_from_world.rotation == b.camera_from_world.rotation &&
         a.camera_from_world.translation == b.camera_from_world.translation;
}

}  // namespace

absl::StatusOr<std::vector<RefinementView>> GeneratedRefinementViews(
    const GaussianCloud& object, const std::vector<PinholeCamera>& ring, const ObjectFrame& frame,
    const std::vector<ViewImages>& images, int num_threads) {
  std::vector<RefinementView> views;
  for (const PinholeCamera& camera : ring) {
    RefinementView view;
    view.camera = camera;
    view.generated = true;
    view.near_plane = NearPlane(camera, frame);
    auto given = std::find_if(images.begin(), images.end(),
                              [&](const ViewImages& v) { return SameCamera(v.camera, camera); });
    if (given != images.end()) {
      view.rgb = given->rgb;
      view.mask = given->mask;
    } else {
      ASSIGN_OR_RETURN(ViewImages rendered, RenderObjectView(object, camera, frame, num_threads));
      view.rgb = std::move(rendered.rgb);
      view.mask = std::move(rendered.mask);
    }
    views.push_back(std::move(view));
  }
  return views;
}

absl::StatusOr<std::optional<RefinementView>> RealRefinementView(
    const PinholeCamera& camera, const Image& image, const GaussianCloud& object,
    const GaussianCloud& scene, const std::vector<uint32_t>& instance, const ObjectFrame& frame,
    int max_side, int num_threads, int min_pixels) {
  if (image.width != camera.width || image.height != camera.height || image.channels < 1 ||
      image.pixels.size() != static_cast<size_t>(image.width) * image.height * image.channels) {
    return absl::InvalidArgumentError(absl::StrCat("refinement: a ", image.width, "x", image.height,
                                                   " image for a ", camera.width, "x",
                                                   camera.height, " camera"));
  }
  if (max_side < 16) return absl::InvalidArgumentError("refinement: max_side < 16");
  RenderOptions options;
  options.depth = true;
  options.color = false;
  options.num_threads = num_threads;
  options.near_plane = NearPlane(camera, frame);
  std::vector<uint8_t> is_instance(scene.size(), 0);
  for (uint32_t g : instance) is_instance.at(g) = 1;
  ASSIGN_OR_RETURN(RenderResult own, Render(scene.Subset(instance), camera, options));
  ASSIGN_OR_RETURN(RenderResult all, Render(scene, camera, options));
  ASSIGN_OR_RETURN(RenderResult whole, Render(object, camera, options));
  const int w = camera.width, h = camera.height;
  int x0 = w, x1 = -1, y0 = h, y1 = -1, seen = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t i = static_cast<size_t>(y) * w + x;
      if (own.alpha[i] > 0.5f) {
        const float depth = own.median_depth[i];
        const float tolerance = 3.0f * frame.spacing + 0.01f * depth;
        seen += !(all.alpha[i] > 0.5f && all.median_depth[i] < depth - tolerance);
      }
      if (!(whole.alpha[i] > 0.5f)) continue;
      x0 = std::min(x0, x);
      x1 = std::max(x1, x);
      y0 = std::min(y0, y);
      y1 = std::max(y1, y);
    }
  }
  if (seen < min_pixels || x1 < 0) return std::nullopt;
  constexpr int kMargin = 4;
  x0 = std::max(0, x0 - kMargin);
  y0 = std::max(0, y0 - kMargin);
  x1 = std::min(w - 1, x1 + kMargin);
  y1 = std::min(h - 1, y1 + kMargin);
  const int crop_w = x1 - x0 + 1, crop_h = y1 - y0 + 1;
  const int factor = (std::max(crop_w, crop_h) + max_side - 1) / max_side;
  const int out_w = crop_w / factor, out_h = crop_h / factor;
  if (out_w < 1 || out_h < 1) return std::nullopt;
  RefinementView view;
  view.camera = camera;
  view.camera.width = out_w;
  view.camera.height = out_h;
  view.camera.cx = (camera.cx - x0) / factor;
  view.camera.cy = (camera.cy - y0) / factor;
  view.camera.fx = camera.fx / factor;
  view.camera.fy = camera.fy / factor;
  view.near_plane = options.near_plane;
  // The context: every non-instance surfel that touches the crop.
  RenderOptions probe = options;
  probe.depth = false;
  ASSIGN_OR_RETURN(RenderResult crop, Render(scene, view.camera, probe));
  std::vector<uint32_t> context;
  for (uint32_t g = 0; g < scene.size(); ++g) {
    if (crop.visible[g] && !is_instance[g]) context.push_back(g);
  }
  view.context = scene.Subset(context);
  view.context.extras.clear();
  view.rgb.assign(static_cast<size_t>(3) * out_w * out_h, 0.0f);
  view.mask.assign(static_cast<size_t>(out_w) * out_h, 1);
  const int channels = image.channels;
  const float inv = 1.0f / (factor * factor);
  for (int y = 0; y < out_h; ++y) {
    for (int x = 0; x < out_w; ++x) {
      float rgb[3] = {0, 0, 0};
      for (int dy = 0; dy < factor; ++dy) {
        for (int dx = 0; dx < factor; ++dx) {
          const size_t i = static_cast<size_t>(y0 + y * factor + dy) * w + x0 + x * factor + dx;
          for (int c = 0; c < 3; ++c)
            rgb[c] += image.pixels[i * channels + (channels >= 3 ? c : 0)];
        }
      }
      const size_t o = static_cast<size_t>(y) * out_w + x;
      for (int c = 0; c < 3; ++c) view.rgb[3 * o + c] = rgb[c] * inv;
    }
  }
  return view;
}

}  // namespace instascene::generation
