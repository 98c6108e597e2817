// services/generation/diffusion/ddim.h: the DDIM sampler of the diffusion prior (ALGORITHM.md
// 7.5-7.6): the "scaled linear" schedule (beta_t = (linspace(sqrt(0.00085), sqrt(0.012), T))^2,
// T = 1000), uniform steps (t = T - T/steps, ..., T/steps, 0), the DDIM update
//   x0 = (x_t - sqrt(1 - a_t) eps) / sqrt(a_t)
//   x_prev = sqrt(a_prev) x0 + sqrt(1 - a_prev - sigma^2) eps + sigma z,
//   sigma = eta sqrt((1 - a_prev) / (1 - a_t) (1 - a_t / a_prev)),
// with a_prev = 1 after the last step (so no noise there), classifier-free guidance
// eps = eps_u + w (eps_c - eps_u), and the paper's alternated conditioning (Eq. 9): every target's
// noise is predicted once per known condition view and averaged. Deterministic for a seed (one
// standard-normal stream per target, drawn in step order). Thread-compatible.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "absl/status/statusor.h"
#include "services/generation/diffusion/denoiser.h"

namespace instascene::generation::diffusion {

struct NoiseSchedule {
  std::vector<double> alphas_cumprod;  // a_t, t = 0..T-1

  // The scaled-linear schedule of Stable Diffusion / MVD-Fusion.
  static NoiseSchedule ScaledLinear(int steps = 1000, double beta_start = 0.00085,
                                    double beta_end = 0.012);
  int size() const { return static_cast<int>(alphas_cumprod.size()); }
};

struct DdimOptions {
  int steps = 50;         // uniform over the schedule
  double eta = 1.0;       // MVD-Fusion's sampler
  double guidance = 1.0;  // classifier-free guidance scale (1 = conditional only, no unconditional)
  uint64_t seed = 1;
};

// What the sampler does after each step (e.g. the latent warping's RePaint-style replacement of
// known pixels): called with the step index, the timestep the latents are now at (-1 after the
// last step) and every target's latent, which it may change. Returning an error stops sampling.
using StepHook =
    std::function<absl::Status(int step, int timestep, std::vector<std::vector<float>>* latents)>;

// Samples `targets` latents of `latent_size` values each, conditioned on every id in
// `conditions` (averaged, Eq. 9; at least one). A denoiser answer of the wrong size or with a
// non-finite value fails with InvalidArgument naming the target, condition and timestep; the
// denoiser's own errors are passed on.
absl::StatusOr<std::vector<std::vector<float>>> SampleDdim(
    const Denoiser& denoiser, const NoiseSchedule& schedule, int targets, int latent_size,
    const std::vector<int>& conditions, const DdimOptions& options, const StepHook& hook = nullptr);

// The timesteps the sampler visits, first to last.
std::vector<int> DdimTimesteps(const NoiseSchedule& schedule, int steps);

}  // namespace instascene::generation::diffusion
