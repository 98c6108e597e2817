#include "services/generation/diffusion/analytic_denoiser.h"

#include <cmath>

#include "absl/strings/str_cat.h"

namespace instascene::generation::diffusion {

AnalyticDenoiser::AnalyticDenoiser(NoiseSchedule schedule, std::vector<double> means,
                                   double uncond_mean, double stddev)
    : schedule_(std::move(schedule)),
      means_(std::move(means)),
      uncond_mean_(uncond_mean),
      variance_(stddev * stddev) {}

absl::StatusOr<std::vector<float>> AnalyticDenoiser::PredictNoise(const NoiseQuery& q) const {
  if (q.timestep < 0 || q.timestep >= schedule_.size())
    return absl::OutOfRangeError(absl::StrCat("timestep ", q.timestep));
  if (q.condition >= static_cast<int>(means_.size()))
    return absl::OutOfRangeError(absl::StrCat("condition ", q.condition));
  const double mu = q.condition < 0 ? uncond_mean_ : means_[q.condition];
  const double a = schedule_.alphas_cumprod[q.timestep];
  const double gain = std::sqrt(1.0 - a) / (a * variance_ + 1.0 - a);
  std::vector<float> eps(q.latent->size());
  for (size_t j = 0; j < eps.size(); ++j) {
    eps[j] = static_cast<float>(gain * ((*q.latent)[j] - std::sqrt(a) * mu));
  }
  return eps;
}

Moments ExactDdimMoments(const NoiseSchedule& schedule, const DdimOptions& options, double mu,
                         double s) {
  const std::vector<int> timesteps = DdimTimesteps(schedule, options.steps);
  Moments m{0.0, 1.0};
  for (size_t i = 0; i < timesteps.size(); ++i) {
    const double a_t = schedule.alphas_cumprod[timesteps[i]];
    const double a_prev =
        i + 1 < timesteps.size() ? schedule.alphas_cumprod[timesteps[i + 1]] : 1.0;
    const double sigma =
        options.eta * std::sqrt((1.0 - a_prev) / (1.0 - a_t) * (1.0 - a_t / a_prev));
    const double dir = std::sqrt(std::max(0.0, 1.0 - a_prev - sigma * sigma));
    // eps = g (x - sqrt(a) mu); x0 = (x - sqrt(1-a) eps) / sqrt(a); x' = sqrt(a') x0 + dir eps.
    const double g = std::sqrt(1.0 - a_t) / (a_t * s * s + 1.0 - a_t);
    const double eps_x = g, eps_c = -g * std::sqrt(a_t) * mu;
    const double x0_x = (1.0 - std::sqrt(1.0 - a_t) * eps_x) / std::sqrt(a_t);
    const double x0_c = -std::sqrt(1.0 - a_t) * eps_c / std::sqrt(a_t);
    const double A = std::sqrt(a_prev) * x0_x + dir * eps_x;
    const double B = std::sqrt(a_prev) * x0_c + dir * eps_c;
    m.mean = A * m.mean + B;
    m.variance = A * A * m.variance + sigma * sigma;
  }
  return m;
}

}  // namespace instascene::generation::diffusion
