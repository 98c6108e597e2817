// services/generation/diffusion/analytic_denoiser.h: the optimal noise predictor for Gaussian
// data, whose right answer is known (issue 18). If every latent value is x0 ~ N(mu, s^2)
// independently, then x_t = sqrt(a_t) x0 + sqrt(1 - a_t) eps has
//   E[eps | x_t] = sqrt(1 - a_t) (x_t - sqrt(a_t) mu) / (a_t s^2 + 1 - a_t),
// the minimiser of the denoising loss. Each condition view k has its own data mean mu_k (the
// unconditional one mu_u), so averaging predictions over conditions is the analytic answer for
// the averaged mean, and guidance w moves the mean to mu_u + w (mu_k - mu_u). Thread-safe.
#pragma once

#include <vector>

#include "services/generation/diffusion/ddim.h"
#include "services/generation/diffusion/denoiser.h"

namespace instascene::generation::diffusion {

class AnalyticDenoiser : public Denoiser {
 public:
  // means[k]: the data mean under condition k; uncond_mean: without a condition.
  AnalyticDenoiser(NoiseSchedule schedule, std::vector<double> means, double uncond_mean,
                   double stddev);
  absl::StatusOr<std::vector<float>> PredictNoise(const NoiseQuery& query) const override;

 private:
  NoiseSchedule schedule_;
  std::vector<double> means_;
  double uncond_mean_, variance_;
};

// The exact mean and variance of one latent value after SampleDdim with a denoiser whose every
// prediction is affine in x_t as the analytic one's (mean `mu`, stddev `s`): each DDIM step is
// then x_prev = A x_t + B + sigma z, so the moments propagate in closed form from N(0, 1).
struct Moments {
  double mean = 0, variance = 0;
};
Moments ExactDdimMoments(const NoiseSchedule& schedule, const DdimOptions& options, double mu,
                         double s);

}  // namespace instascene::generation::diffusion
