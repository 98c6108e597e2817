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

// The crop of a real view: the object's pixel box with a margin, binned by `factor`.
struct Crop {
  int x0 = 0, y0 = 0, factor = 1, width = 0, height = 0;
};

// The object's box in the view (the whole completed object's render) and how many of the
// instance's own pixels no other surface hides; nullopt when fewer than min_pixels show or the
// crop is empty.
absl::StatusOr<std::optional<Crop>> VisibleCrop(
    const PinholeCamera& camera, const GaussianCloud& object, const GaussianCloud& scene,
    const std::vector<uint32_t>& instance, const ObjectFrame& frame, const RenderOptions& options,
    int max_side, int min_pixels) {
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
  Crop c;
  c.x0 = std::max(0, x0 - kMargin);
  c.y0 = std::max(0, y0 - kMargin);
  x1 = std::min(w - 1, x1 + kMargin);
  y1 = std::min(h - 1, y1 + kMargin);
  const int crop_w = x1 - c.x0 + 1, crop_h = y1 - c.y0 + 1;
  c.factor = (std::max(crop_w, crop_h) + max_side - 1) / max_side;
  c.width = crop_w / c.factor;
  c.height = crop_h / c.factor;
  if (c.width < 1 || c.height < 1) return std::nullopt;
  return c;
}

// The image's crop, box-filtered by the crop's factor, as RGB.
std::vector<float> BinnedCrop(const Image& image, const Crop& c) {
  std::vector<float> rgb_out(static_cast<size_t>(3) * c.width * c.height, 0.0f);
  const int channels = image.channels;
  const float inv = 1.0f / (c.factor * c.factor);
  for (int y = 0; y < c.height; ++y) {
    for (int x = 0; x < c.width; ++x) {
      float rgb[3] = {0, 0, 0};
      for (int dy = 0; dy < c.factor; ++dy) {
        for (int dx = 0; dx < c.factor; ++dx) {
          const size_t i = static_cast<size_t>(c.y0 + y * c.factor + dy) * image.width + c.x0 +
                           x * c.factor + dx;
          for (int ch = 0; ch < 3; ++ch)
            rgb[ch] += image.pixels[i * channels + (channels >= 3 ? ch : 0)];
        }
      }
      const size_t o = static_cast<size_t>(y) * c.width + x;
      for (int ch = 0; ch < 3; ++ch) rgb_out[3 * o + ch] = rgb[ch] * inv;
    }
  }
  return rgb_out;
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
  ASSIGN_OR_RETURN(
      const std::optional<Crop> crop,
      VisibleCrop(camera, object, scene, instance, frame, options, max_side, min_pixels));
  if (!crop) return std::nullopt;
  RefinementView view;
  view.camera = camera;
  view.camera.width = crop->width;
  view.camera.height = crop->height;
  view.camera.cx = (camera.cx - crop->x0) / crop->factor;
  view.camera.cy = (camera.cy - crop->y0) / crop->factor;
  view.camera.fx = camera.fx / crop->factor;
  view.camera.fy = camera.fy / crop->factor;
  view.near_plane = options.near_plane;
  // The context: every non-instance surfel that touches the crop.
  RenderOptions probe = options;
  probe.depth = false;
  ASSIGN_OR_RETURN(RenderResult touched, Render(scene, view.camera, probe));
  std::vector<uint32_t> context;
  for (uint32_t g = 0; g < scene.size(); ++g) {
    if (touched.visible[g] && !is_instance[g]) context.push_back(g);
  }
  view.context = scene.Subset(context);
  view.context.extras.clear();
  view.rgb = BinnedCrop(image, *crop);
  view.mask.assign(static_cast<size_t>(crop->width) * crop->height, 1);
  return view;
}

}  // namespace instascene::generation
