#include "services/generation/diffusion/latent_views.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "services/generation/diffusion/unseen_region.h"

namespace instascene::generation::diffusion {
namespace {

// The camera of the latent grid: the view scaled to n x n.
PinholeCamera LatentCamera(const PinholeCamera& c, int n) {
  return c.Scaled(static_cast<double>(n) / c.width);
}

// A warp at image resolution brought to the n x n latent grid: a cell is known where more than
// half of its pixels are, with the mean depth of those pixels; its latent is the codec's encoding
// of the warped image in which each unknown pixel takes its cell's known mean (white in cells
// with none), so that for the identity codec a known cell is exactly the mean of its known
// pixels.
absl::StatusOr<WarpResult> EncodeWarp(const WarpResult& pixels, const LatentCodec& codec, int width,
                                      int height, int n) {
  const int cells = n * n;
  WarpResult out;
  out.known.assign(cells, 0);
  out.depth.assign(cells, 0.0f);
  std::vector<int> total(cells, 0), known(cells, 0);
  std::vector<double> sum(static_cast<size_t>(3) * cells, 0.0), depth(cells, 0.0);
  auto cell_of = [&](int x, int y) {
    return static_cast<size_t>(y * n / height) * n + x * n / width;
  };
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const size_t cell = cell_of(x, y), i = static_cast<size_t>(y) * width + x;
      ++total[cell];
      if (!pixels.known[i]) continue;
      ++known[cell];
      depth[cell] += pixels.depth[i];
      for (int c = 0; c < 3; ++c) sum[cell * 3 + c] += pixels.values[i * 3 + c];
    }
  }
  std::vector<float> image(static_cast<size_t>(3) * width * height, 1.0f);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const size_t cell = cell_of(x, y), i = static_cast<size_t>(y) * width + x;
      for (int c = 0; c < 3; ++c) {
        image[i * 3 + c] = pixels.known[i]   ? pixels.values[i * 3 + c]
                           : known[cell] > 0 ? static_cast<float>(sum[cell * 3 + c] / known[cell])
                                             : 1.0f;
      }
    }
  }
  ASSIGN_OR_RETURN(const std::vector<float> latent, codec.Encode(image, width, height));
  const int channels = static_cast<int>(latent.size()) / cells;
  out.values.assign(latent.size(), 0.0f);
  for (int c = 0; c < channels; ++c) {
    for (int cell = 0; cell < cells; ++cell)
      out.values[cell * channels + c] = latent[c * cells + cell];
  }
  for (int cell = 0; cell < cells; ++cell) {
    if (2 * known[cell] <= total[cell]) continue;
    out.known[cell] = 1;
    ++out.written;
    out.depth[cell] = static_cast<float>(depth[cell] / known[cell]);
  }
  return out;
}

// The depth channel of a known view: per cell, the mean code of its masked pixels where most are
// masked, else the background.
std::vector<float> DepthChannel(const ViewImages& v, const ObjectFrame& frame, int n) {
  const DepthCode code(v.camera, frame);
  const int w = v.camera.width, h = v.camera.height;
  std::vector<double> sum(static_cast<size_t>(n) * n, 0.0);
  std::vector<int> total(sum.size(), 0), masked(sum.size(), 0);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t cell = static_cast<size_t>(y * n / h) * n + x * n / w;
      const size_t i = static_cast<size_t>(y) * w + x;
      ++total[cell];
      if (i >= v.mask.size() || !v.mask[i] || i >= v.depth.size() || !(v.depth[i] > 0)) continue;
      ++masked[cell];
      sum[cell] += code.Encode(v.depth[i]);
    }
  }
  std::vector<float> out(sum.size(), kBackgroundDepthCode);
  for (size_t cell = 0; cell < out.size(); ++cell) {
    if (2 * masked[cell] > total[cell]) out[cell] = static_cast<float>(sum[cell] / masked[cell]);
  }
  return out;
}

// z of the first instance hit of every pixel of `camera` (0 = miss).
std::vector<float> InstanceDepth(const RayCaster& mesh, const PinholeCamera& camera) {
  std::vector<float> depth(static_cast<size_t>(camera.width) * camera.height, 0.0f);
  const Eigen::Vector3f eye = camera.CenterInWorld().cast<float>();
  const Eigen::Vector3f axis = camera.camera_from_world.rotation.row(2).transpose().cast<float>();
  for (int row = 0; row < camera.height; ++row) {
    for (int col = 0; col < camera.width; ++col) {
      const Eigen::Vector3f dir = camera.PixelRayInWorld(col, row).cast<float>();
      const RayHit hit = mesh.Cast(eye, dir);
      if (hit.hit)
        depth[static_cast<size_t>(row) * camera.width + col] = hit.distance * dir.dot(axis);
    }
  }
  return depth;
}

}  // namespace

int CodecChannels(const std::shared_ptr<const LatentCodec>& codec, int n) {
  return codec ? codec->latent_values() / (n * n) : 3;
}

absl::StatusOr<KnownViews> EncodeKnownViews(const PriorInput& input, const LatentCodec& codec,
                                            int n, int channels, bool pixel_warp) {
  const int cells = n * n;
  KnownViews out;
  for (const ViewImages& v : input.conditions) {
    ASSIGN_OR_RETURN(std::vector<float> latent,
                     codec.Encode(v.rgb, v.camera.width, v.camera.height));
    if (pixel_warp) {
      out.warp_sources.push_back(KnownView{v.camera, v.rgb});  // [0, 1], HxWx3
    } else {
      KnownView k{LatentCamera(v.camera, n),
                  std::vector<float>(static_cast<size_t>(channels) * cells)};
      for (int c = 0; c < channels; ++c) {
        for (int cell = 0; cell < cells; ++cell)
          k.values[cell * channels + c] = latent[c * cells + cell];
      }
      out.warp_sources.push_back(std::move(k));
    }
    const std::vector<float> depth = DepthChannel(v, input.frame, n);
    latent.insert(latent.end(), depth.begin(), depth.end());
    out.condition_latents.push_back(std::move(latent));
  }
  return out;
}

absl::StatusOr<TargetPlan> PlanTarget(const PinholeCamera& target,
                                      const std::vector<KnownView>& known, const RayCaster& mesh,
                                      const LatentCodec& codec, const PriorInput& input, int n,
                                      int channels, bool pixel_warp, bool unseen_mask) {
  const int cells = n * n;
  std::vector<KnownView> order = known;
  const Eigen::Vector3d dir_t = target.camera_from_world.rotation.row(2).transpose();
  std::stable_sort(order.begin(), order.end(), [&](const KnownView& a, const KnownView& b) {
    return a.camera.camera_from_world.rotation.row(2).dot(dir_t.transpose()) >
           b.camera.camera_from_world.rotation.row(2).dot(dir_t.transpose());
  });
  const PinholeCamera grid = LatentCamera(target, n);
  TargetPlan plan;
  WarpOptions warp_options;
  warp_options.channels = pixel_warp ? 3 : channels;
  ASSIGN_OR_RETURN(plan.warp,
                   WarpIntoTarget(mesh, order, pixel_warp ? target : grid, warp_options));
  if (pixel_warp) {
    ASSIGN_OR_RETURN(plan.warp, EncodeWarp(plan.warp, codec, target.width, target.height, n));
  }
  const std::vector<float> hits = InstanceDepth(mesh, grid);
  const DepthCode code(target, input.frame);
  plan.depth_code.assign(cells, kBackgroundDepthCode);
  for (int cell = 0; cell < cells; ++cell) {
    if (plan.warp.known[cell]) plan.depth_code[cell] = code.Encode(plan.warp.depth[cell]);
  }
  plan.background.assign(cells, 0);
  if (unseen_mask) {
    const std::vector<uint8_t> unseen =
        UnseenRegion(*input.free_space, input.frame, grid, hits, target.width);
    for (int cell = 0; cell < cells; ++cell)
      plan.background[cell] = !plan.warp.known[cell] && !unseen[cell] && !(hits[cell] > 0);
  }
  for (int cell = 0; cell < cells; ++cell)
    plan.generated += !plan.warp.known[cell] && !plan.background[cell];
  return plan;
}

absl::StatusOr<ViewImages> DecodeTarget(const std::vector<float>& latent, const PinholeCamera& cam,
                                        const LatentCodec& codec, const ObjectFrame& frame, int n,
                                        int channels, int64_t* object_pixels) {
  const int cells = n * n;
  ViewImages v;
  v.camera = cam;
  const size_t pixels = static_cast<size_t>(cam.width) * cam.height;
  const std::vector<float> colour(latent.begin(), latent.begin() + channels * cells);
  ASSIGN_OR_RETURN(v.rgb, codec.Decode(colour, cam.width, cam.height));
  if (v.rgb.size() != 3 * pixels)
    return absl::InternalError(absl::StrCat("diffusion prior: the codec ", codec.name(),
                                            " decoded ", v.rgb.size(), " values for ", cam.width,
                                            "x", cam.height, "x3"));
  const DepthCode code(cam, frame);
  v.alpha.assign(pixels, 0.0f);
  v.mask.assign(pixels, 0);
  v.depth.assign(pixels, 0.0f);
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const size_t i = static_cast<size_t>(y) * cam.width + x;
      const float d = latent[channels * cells + (y * n / cam.height) * n + x * n / cam.width];
      if (!(d < kSurfaceDepthCode)) continue;
      v.mask[i] = 1;
      v.alpha[i] = 1.0f;
      v.depth[i] = static_cast<float>(std::max(code.Decode(d), 1e-6));
      ++*object_pixels;
    }
  }
  return v;
}

}  // namespace instascene::generation::diffusion
