#include "services/generation/diffusion/ddim.h"

#include <cmath>
#include <random>

#include "absl/strings/str_cat.h"

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
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<std::vector<float>> x(targets, std::vector<float>(latent_size));
  for (int n = 0; n < targets; ++n) {
    for (float& v : x[n]) v = static_cast<float>(normal(rngs[n]));
  }
  auto predict = [&](int n, int t, int condition) -> absl::StatusOr<std::vector<float>> {
    NoiseQuery q{&x[n], t, n, condition};
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
  };
  const bool guided = options.guidance != 1.0;
  for (size_t i = 0; i < timesteps.size(); ++i) {
    const int t = timesteps[i];
    const double a_t = schedule.alphas_cumprod[t];
    const double a_prev =
        i + 1 < timesteps.size() ? schedule.alphas_cumprod[timesteps[i + 1]] : 1.0;
    const double sigma =
        options.eta * std::sqrt((1.0 - a_prev) / (1.0 - a_t) * (1.0 - a_t / a_prev));
    const double dir = std::sqrt(std::max(0.0, 1.0 - a_prev - sigma * sigma));
    for (int n = 0; n < targets; ++n) {
      // Eq. 9: the (guided) noise averaged over the condition views.
      std::vector<double> eps(latent_size, 0.0);
      std::vector<float> uncond;
      if (guided) {
        absl::StatusOr<std::vector<float>> u = predict(n, t, -1);
        if (!u.ok()) return u.status();
        uncond = std::move(*u);
      }
      for (int condition : conditions) {
        absl::StatusOr<std::vector<float>> c = predict(n, t, condition);
        if (!c.ok()) return c.status();
        for (int j = 0; j < latent_size; ++j) {
          eps[j] += guided ? uncond[j] + options.guidance * ((*c)[j] - uncond[j]) : (*c)[j];
        }
      }
      for (double& e : eps) e /= static_cast<double>(conditions.size());
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
