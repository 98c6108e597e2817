// services/generation/diffusion/diffusion_prior.h: the `diffusion` completion prior (issue 18;
// GENERATION.md step 4; ALGORITHM.md 7.5-7.7). Known ring views are the conditions, unknown ring
// views the targets; each target starts from noise, its latent's pixels that a known view sees
// (geometry-aware warping through a mesh of the observed surfels, nearest azimuth first) are
// replaced at every step by the known latent noised to the step's level (RePaint-style); the
// DDIM sampler averages the denoiser's noise over the conditions (Eq. 9). The VAE is an interface
// (latent_codec.h), the identity by default: a latent is the RGB image area-averaged to
// latent_size² and mapped to [-1, 1]; a depth channel travels with it (below). The output is
// one generated view per target: RGB, depth and mask (from the depth channel), which the joint
// refinement fits. No weights ship
// with the project: the denoiser is a gRPC service (grpc://HOST:PORT) or an ONNX file a site
// supplies (onnx:FILE.json). Thread-compatible.
#pragma once

#include <memory>
#include <string>

#include "services/generation/diffusion/ddim.h"
#include "services/generation/diffusion/denoiser.h"
#include "services/generation/diffusion/latent_codec.h"
#include "services/generation/prior.h"

namespace instascene::generation::diffusion {

// The two choices ALGORITHM.md 7.7 leaves open, as parameters:
// - replace_fraction: the share of the steps, from the noisiest, at which known pixels replace the
//   sampler's. Default 1 (every step, RePaint): the paper keeps the warped known content in the
//   visible target pixels, and with it the generated views agree with the known ones to the last
//   step; a smaller share lets the denoiser harmonise the seams at the end at the price of drift
//   in the known pixels (diffusion_test measures both).
// - warp: "latent" warps the known latents on the latent grid (one ray per latent cell: cheap, the
//   paper's wording "move the known-view latents"); "pixel" warps the known images at the ring's
//   resolution and encodes the result (a latent cell is known where most of its pixels are, and
//   takes the mean of those): finer visibility and culling at 64x the rays. Default "latent".
// The denoiser's latent is the codec's C x n x n colour latent (the identity's C = 3; a Stable
// Diffusion VAE's C = 4) followed by one n x n depth channel (MVD-Fusion's [5, 32, 32]): z in the
// view's camera relative to the object centre's depth, in object diameters, clamped to [-1, 1];
// background cells are +1. Known views give it from their rendered depth, warped cells from the
// instance hit in the target, generated cells from the sampler. A decoded pixel whose code is below
// kSurfaceDepthCode is the object: mask 1, depth decoded; else background (mask 0, depth 0).
inline constexpr float kBackgroundDepthCode = 1.0f;
inline constexpr int kMaxCodecChannels = 16;
inline constexpr float kSurfaceDepthCode = 0.75f;

struct DiffusionPriorOptions {
  int latent_size = 32;           // latent grid per side (MVD-Fusion: 32 for 256² views)
  DdimOptions ddim;               // 50 steps, eta 1
  double guidance = 2.5;          // classifier-free guidance (MVD-Fusion's scale)
  bool replace_known = true;      // RePaint-style replacement of warped known pixels
  double replace_fraction = 1.0;  // ... during this share of the steps (from t = T)
  std::string warp = "latent";    // latent | pixel
  // ALGORITHM.md 7.8 as the generation mask (unseen_region.h): cells whose ray meets neither the
  // object nor space no real view saw are pinned to the background like known cells are pinned
  // to their content. Needs PriorInput::free_space (off without it).
  bool unseen_mask = true;
  // The image encoder / decoder around the denoiser; null = IdentityCodec(latent_size). Its
  // latents must be C x latent_size², C <= kMaxCodecChannels (the warping moves them
  // spatially).
  std::shared_ptr<const LatentCodec> codec;
};

class DiffusionPrior : public CompletionPrior {
 public:
  // `denoiser` must outlive the prior; `where` names it in messages.
  DiffusionPrior(std::shared_ptr<const Denoiser> denoiser, std::string where,
                 DiffusionPriorOptions options = {});
  std::string name() const override { return "diffusion"; }
  absl::StatusOr<PriorOutput> Complete(const PriorInput& input) const override;

 private:
  std::shared_ptr<const Denoiser> denoiser_;
  std::string where_;
  DiffusionPriorOptions options_;
};

// The prior for a denoiser URI: "grpc://HOST:PORT" (the Denoiser service) or "onnx:FILE.json"
// (an ONNX model run by OpenCV, onnx_denoiser.h; its latent_shape [3, n, n] sets the latent grid;
// loaded and probed here, so a broken model fails before any work). Anything else is
// InvalidArgument, as are settings out of range.
absl::StatusOr<std::unique_ptr<CompletionPrior>> MakeDiffusionPrior(
    const std::string& denoiser, const DiffusionSettings& settings = {});

}  // namespace instascene::generation::diffusion
