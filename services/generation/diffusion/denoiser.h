// services/generation/diffusion/denoiser.h: the noise predictor behind the diffusion prior
// (issue 18; ALGORITHM.md 7.5-7.6). A real model (MVD-Fusion on a GPU) sits behind this interface
// (a gRPC `Denoiser` service, grpc_denoiser.h, or an ONNX file, onnx_denoiser.h); the analytic
// denoiser (analytic_denoiser.h) proves the sampler's maths with a known answer. No weights ship
// with the project.
#pragma once

#include <array>
#include <vector>

#include "absl/status/statusor.h"

namespace instascene::generation::diffusion {

// The largest latent any denoiser takes (values; e.g. [16, 64, 64]); MVD-Fusion's is [5, 32, 32].
inline constexpr int kMaxValuesPerLatent = 65536;

// One noise prediction: the noisy latent of target view `target` at diffusion timestep
// `timestep` (0..T-1), conditioned on known view `condition` (the target's pose is taken relative
// to it), or unconditional (condition = -1, for classifier-free guidance).
struct NoiseQuery {
  const std::vector<float>* latent = nullptr;  // C x H x W, row-major
  int timestep = 0;
  int target = 0;
  int condition = -1;
  // What a real model conditions on (set by the diffusion prior for a conditional query; null
  // for the unconditional one): the condition view's clean latent (the latent's size) and the
  // target camera relative to the condition camera (camera_from_world of the target times
  // world_from_camera of the condition, 4x4 row-major, OpenCV axes).
  const std::vector<float>* condition_latent = nullptr;
  const std::array<double, 16>* target_from_condition = nullptr;
};

class Denoiser {
 public:
  virtual ~Denoiser() = default;
  // Predicted noise, the latent's size. Implementations must be thread-compatible; the sampler
  // calls one at a time.
  virtual absl::StatusOr<std::vector<float>> PredictNoise(const NoiseQuery& query) const = 0;
};

}  // namespace instascene::generation::diffusion
