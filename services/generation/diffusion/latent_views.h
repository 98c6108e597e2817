// services/generation/diffusion/latent_views.h: the diffusion prior's views on the latent grid
// (DiffusionPrior, diffusion_prior.h): the known ring views encoded (colour latent + depth
// channel), each target view's plan (the known views warped into it, their depth codes, the cells
// pinned to the background), the pinned cells' clean values for the sampler, and a sampled target
// latent decoded back into images.
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <vector>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/mesh/ray_caster.h"
#include "services/generation/diffusion/diffusion_prior.h"
#include "services/generation/diffusion/latent_codec.h"
#include "services/generation/diffusion/warping.h"

namespace instascene::generation::diffusion {

// The depth channel's code (DiffusionPriorOptions): z relative to the object centre's depth in
// units of the object's diameter, clamped to [-1, 1]; +1 is also the background.
struct DepthCode {
  double centre_z = 0, diameter = 1;
  DepthCode(const PinholeCamera& camera, const ObjectFrame& frame)
      : centre_z((camera.camera_from_world * frame.center.cast<double>()).z()),
        diameter(std::max(2.0 * frame.radius, 1e-9)) {}
  float Encode(double z) const {
    return static_cast<float>(std::clamp((z - centre_z) / diameter, -1.0, 1.0));
  }
  double Decode(float code) const { return centre_z + diameter * code; }
};

// What the sampler is told about one target's latent cells: the warped known content (colour
// latent and depth code) and the cells pinned to the background.
struct TargetPlan {
  WarpResult warp;                  // on the latent grid
  std::vector<float> depth_code;    // n x n: the known cells' depth code (DepthCode)
  std::vector<uint8_t> background;  // n x n
  int64_t generated = 0;            // cells neither known nor background
};

// The codec's channels on an n x n grid (the identity's 3 when there is none).
int CodecChannels(const std::shared_ptr<const LatentCodec>& codec, int n);

// The known ring views as the sampler sees them: what the denoiser conditions on (colour latent
// + depth channel per view) and what the warper copies (the colour latent on the latent grid, or
// the image itself with a pixel warp).
struct KnownViews {
  std::vector<KnownView> warp_sources;
  std::vector<std::vector<float>> condition_latents;
};

// The known ring views encoded: `channels` colour latent channels on the n x n grid (the
// codec's), the depth channel appended to each condition latent.
absl::StatusOr<KnownViews> EncodeKnownViews(const PriorInput& input, const LatentCodec& codec,
                                            int n, int channels, bool pixel_warp);

// One target view's plan: the known views warped into it (nearest first, by the angle between
// viewing directions), their depth codes, and with the unseen mask the cells pinned to the
// background (neither known, nor looking at unseen space, nor at the object).
absl::StatusOr<TargetPlan> PlanTarget(const PinholeCamera& target,
                                      const std::vector<KnownView>& known, const RayCaster& mesh,
                                      const LatentCodec& codec, const PriorInput& input, int n,
                                      int channels, bool pixel_warp, bool unseen_mask);

// The clean value of every pinned channel of a target's cell (colour latent, then depth code):
// the warped known content, or the background; false when the sampler generates the cell.
class PinnedCells {
 public:
  PinnedCells(const std::vector<TargetPlan>& plans, const std::vector<float>& background_latent,
              int channels, int cells)
      : plans_(plans), background_(background_latent), channels_(channels), cells_(cells) {}
  bool operator()(size_t t, int cell, float* x0) const {
    const TargetPlan& plan = plans_[t];
    if (plan.warp.known[cell]) {
      for (int c = 0; c < channels_; ++c) x0[c] = plan.warp.values[cell * channels_ + c];
      x0[channels_] = plan.depth_code[cell];
      return true;
    }
    if (!plan.background[cell]) return false;
    for (int c = 0; c < channels_; ++c) x0[c] = background_[c * cells_ + cell];
    x0[channels_] = kBackgroundDepthCode;
    return true;
  }

 private:
  const std::vector<TargetPlan>& plans_;
  const std::vector<float>& background_;
  int channels_, cells_;
};

// A sampled target latent decoded: colour through the codec; depth and mask from the depth
// channel (object pixels counted into `object_pixels`).
absl::StatusOr<ViewImages> DecodeTarget(const std::vector<float>& latent, const PinholeCamera& cam,
                                        const LatentCodec& codec, const ObjectFrame& frame, int n,
                                        int channels, int64_t* object_pixels);

}  // namespace instascene::generation::diffusion
