#include "services/generation/diffusion/ddim.h"

#include <cmath>
#include <random>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene::generation::diffusion {

NoiseSchedule NoiseSchedule::ScaledLinear(int steps, double beta_start, double beta_end) {
  NoiseSchedule s;
  s.alphas_cumprod.resize(steps);
  const double a = std::sqrt(beta_start), b = std::sqrt(beta_end);
  double product = 1.0;
  for (int t = 0; t < steps; ++t) {
    const double root = steps > 1 ? a + (b - a) * t / (steps - 1) : a;
    product *= 1.0 - root * root;
    s.alphas_cumprod[t] = product;
  }
  return s;
}

std::vector<int> DdimTimesteps(const NoiseSchedule& schedule, int steps) {
  const int stride = schedule.size() / steps;
  std::vector<int> out;
  for (int i = steps - 1; i >= 0; --i) out.push_back(i * stride);
  return out;
}

namespace {

// The denoiser's noise for target n's latent at timestep t under `condition` (-1: none),
// checked: latent_size finite values.
absl::StatusOr<std::vector<float>> PredictChecked(const Denoiser& denoiser,
                                                  const std::vector<float>& latent, int n, int t,
                                                  int condition, int latent_size) {
  NoiseQuery q{&latent, t, n, condition};
  absl::StatusOr<std::vector<float>> eps = denoiser.PredictNoise(q);
  if (!eps.ok()) return eps.status();
  const std::string where =
      absl::StrCat("denoiser answer for target ", n, ", condition ", condition, ", timestep ", t);
  if (eps->size() != static_cast<size_t>(latent_size))
    return absl::InvalidArgumentError(
        absl::StrCat(where, ": ", eps->size(), " values, expected ", latent_size));
  for (float v : *eps) {
    if (!std::isfinite(v)) return absl::InvalidArgumentError(absl::StrCat(where, ": not finite"));
  }
  return eps;
}

// Eq. 9: target n's (guided) noise averaged over the condition views.
absl::StatusOr<std::vector<double>> AveragedNoise(const Denoiser& denoiser,
                                                  const std::vector<float>& latent, int n, int t,
                                                  const std::vector<int>& conditions,
                                                  double guidance) {
  const int latent_size = static_cast<int>(latent.size());
  const bool guided = guidance != 1.0;
  std::vector<double> eps(latent_size, 0.0);
  std::vector<float> uncond;
  if (guided) {
    ASSIGN_OR_RETURN(uncond, PredictChecked(denoiser, latent, n, t, -1, latent_size));
  }
  for (int condition : conditions) {
    ASSIGN_OR_RETURN(const std::vector<float> c,
                     PredictChecked(denoiser, latent, n, t, condition, latent_size));
    for (int j = 0; j < latent_size; ++j) {
      eps[j] += guided ? uncond[j] + guidance * (c[j] - uncond[j]) : c[j];
    }
  }
  for (double& e : eps) e /= static_cast<double>(conditions.size());
  return eps;
}

}  // namespace

absl::StatusOr<std::vector<std::vector<float>>> SampleDdim(
    const Denoiser& denoiser, const NoiseSchedule& schedule, int targets, int latent_size,
    const std::vector<int>& conditions, const DdimOptions& options, const StepHook& hook) {
  if (targets < 1 || latent_size < 1 || conditions.empty())
    return absl::InvalidArgumentError("ddim: needs targets, a latent size and a condition");
  if (options.steps < 1 || options.steps > schedule.size() || !(options.eta >= 0) ||
      !std::isfinite(options.guidance))
    return absl::InvalidArgumentError(
        absl::StrCat("ddim: steps in [1, ", schedule.size(), "], eta >= 0, finite guidance"));
  const std::vector<int> timesteps = DdimTimesteps(schedule, options.steps);
  std::vector<std::mt19937_64> rngs;
  for (int n = 0; n < targets; ++n) rngs.emplace_back(options.seed * 1000003ULL + n);
  std::normal_distribution<double> normal(0.0, 1.0);  // one, shared in this order by every target
  std::vector<std::vector<float>> x(targets, std::vector<float>(latent_size));
  for (int n = 0; n < targets; ++n) {
    for (float& v : x[n]) v = static_cast<float>(normal(rngs[n]));
  }
  for (size_t i = 0; i < timesteps.size(); ++i) {
    const int t = timesteps[i];
    const double a_t = schedule.alphas_cumprod[t];
    const double a_prev =
        i + 1 < timesteps.size() ? schedule.alphas_cumprod[timesteps[i + 1]] : 1.0;
    const double sigma =
        options.eta * std::sqrt((1.0 - a_prev) / (1.0 - a_t) * (1.0 - a_t / a_prev));
    const double dir = std::sqrt(std::max(0.0, 1.0 - a_prev - sigma * sigma));
    for (int n = 0; n < targets; ++n) {
      ASSIGN_OR_RETURN(const std::vector<double> eps,
                       AveragedNoise(denoiser, x[n], n, t, conditions, options.guidance));
      for (int j = 0; j < latent_size; ++j) {
        const double x0 = (x[n][j] - std::sqrt(1.0 - a_t) * eps[j]) / std::sqrt(a_t);
        double next = std::sqrt(a_prev) * x0 + dir * eps[j];
        if (sigma > 0) next += sigma * normal(rngs[n]);
        x[n][j] = static_cast<float>(next);
      }
    }
    if (hook) {
      const int now = i + 1 < timesteps.size() ? timesteps[i + 1] : -1;
      if (absl::Status s = hook(static_cast<int>(i), now, &x); !s.ok()) return s;
    }
  }
  return x;
}

}  // namespace instascene::generation::diffusion
