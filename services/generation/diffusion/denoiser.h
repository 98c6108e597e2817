// services/generation/diffusion/denoiser.h: the noise predictor behind the diffusion prior
// (issue 18; ALGORITHM.md 7.5-7.6). A real model (MVD-Fusion on a GPU) sits behind this interface
// (a gRPC `Denoiser` service or an ONNX file, not built yet); the analytic denoiser
// (analytic_denoiser.h) proves the sampler's maths with a known answer. No weights ship with the
// project.
#pragma once

#include <vector>

#include "absl/status/statusor.h"

namespace instascene::generation::diffusion {

// One noise prediction: the noisy latent of target view `target` at diffusion timestep
// `timestep` (0..T-1), conditioned on known view `condition` (the target's pose is taken relative
// to it), or unconditional (condition = -1, for classifier-free guidance).
struct NoiseQuery {
  const std::vector<float>* latent = nullptr;  // C x H x W, row-major
  int timestep = 0;
  int target = 0;
  int condition = -1;
};

class Denoiser {
 public:
  virtual ~Denoiser() = default;
  // Predicted noise, the latent's size. Implementations must be thread-compatible; the sampler
  // calls one at a time.
  virtual absl::StatusOr<std::vector<float>> PredictNoise(const NoiseQuery& query) const = 0;
};

}  // namespace instascene::generation::diffusion
