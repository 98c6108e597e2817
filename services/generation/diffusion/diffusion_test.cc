#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>

#include "services/generation/diffusion/analytic_denoiser.h"
#include "services/generation/diffusion/ddim.h"

namespace instascene::generation::diffusion {
namespace {

struct Sampled {
  double mean = 0, variance = 0;
};

Sampled SampleMoments(const std::vector<float>& values) {
  Sampled s;
  for (float v : values) s.mean += v;
  s.mean /= values.size();
  for (float v : values) s.variance += (v - s.mean) * (v - s.mean);
  s.variance /= values.size() - 1;
  return s;
}

TEST(Ddim, ScaledLinearScheduleAndUniformSteps) {
  const NoiseSchedule s = NoiseSchedule::ScaledLinear();
  ASSERT_EQ(s.size(), 1000);
  EXPECT_NEAR(s.alphas_cumprod[0], 1.0 - 0.00085, 1e-12);
  for (int t = 1; t < s.size(); ++t) ASSERT_LT(s.alphas_cumprod[t], s.alphas_cumprod[t - 1]);
  EXPECT_NEAR(s.alphas_cumprod[999], 0.0047, 2e-4);  // Stable Diffusion's final a_T
  const std::vector<int> t = DdimTimesteps(s, 50);
  ASSERT_EQ(t.size(), 50u);
  EXPECT_EQ(t.front(), 980);
  EXPECT_EQ(t[1], 960);
  EXPECT_EQ(t.back(), 0);
}

// Every latent value is an independent sample: 20 000 of them estimate the output distribution.
TEST(Ddim, AnalyticDenoiserSamplesTheDataDistribution) {
  const NoiseSchedule schedule = NoiseSchedule::ScaledLinear();
  const double mu = 0.3, s = 0.5;
  AnalyticDenoiser denoiser(schedule, {mu}, 0.0, s);
  DdimOptions options;
  const int n = 20000;
  auto x = SampleDdim(denoiser, schedule, 1, n, {0}, options);
  ASSERT_TRUE(x.ok()) << x.status();
  const Sampled got = SampleMoments((*x)[0]);
  const Moments exact = ExactDdimMoments(schedule, options, mu, s);
  std::printf(
      "DDIM (50 steps, eta 1) on N(%.2f, %.2f^2): sampled mean %.4f var %.4f; exact "
      "sampler mean %.4f var %.4f; data var %.4f\n",
      mu, s, got.mean, got.variance, exact.mean, exact.variance, s * s);
  // Monte Carlo: 5 standard errors.
  EXPECT_NEAR(got.mean, exact.mean, 5 * std::sqrt(exact.variance / n));
  EXPECT_NEAR(got.variance, exact.variance, 5 * exact.variance * std::sqrt(2.0 / n));
  // The sampler's own error against the data distribution: the mean is kept; the variance falls
  // short because each ancestral step uses E[x0 | x_t] without its posterior spread, a deficit
  // that shrinks with the step size (50 steps: ~19 %; DDPM's 1000: ~1 %).
  EXPECT_NEAR(exact.mean, mu, 0.01);
  EXPECT_NEAR(exact.variance / (s * s), 1.0, 0.25);
  double previous_deficit = 1.0;
  for (int steps : {50, 250, 1000}) {
    DdimOptions o;
    o.steps = steps;
    const Moments m = ExactDdimMoments(schedule, o, mu, s);
    const double deficit = 1.0 - m.variance / (s * s);
    std::printf("  %4d steps: exact mean %.4f, variance %.1f %% short of the data's\n", steps,
                m.mean, 100 * deficit);
    EXPECT_LT(deficit, previous_deficit);
    EXPECT_NEAR(m.mean, mu, 0.01);
    previous_deficit = deficit;
  }
  EXPECT_LT(previous_deficit, 0.03);
}

TEST(Ddim, AveragingIdenticalConditionsEqualsOneCondition) {
  const NoiseSchedule schedule = NoiseSchedule::ScaledLinear();
  AnalyticDenoiser denoiser(schedule, {0.4, 0.4, 0.4}, 0.0, 0.3);
  DdimOptions options;
  auto one = SampleDdim(denoiser, schedule, 2, 500, {0}, options);
  auto three = SampleDdim(denoiser, schedule, 2, 500, {0, 1, 2}, options);
  ASSERT_TRUE(one.ok() && three.ok());
  for (int t = 0; t < 2; ++t) {
    for (int j = 0; j < 500; ++j) ASSERT_NEAR((*one)[t][j], (*three)[t][j], 1e-5);
  }
}

TEST(Ddim, AveragingConditionsIsTheAnalyticAnswerForTheAveragedScore) {
  const NoiseSchedule schedule = NoiseSchedule::ScaledLinear();
  AnalyticDenoiser three(schedule, {0.1, 0.5, 0.9}, 0.0, 0.4);
  AnalyticDenoiser averaged(schedule, {0.5}, 0.0, 0.4);
  DdimOptions options;
  auto a = SampleDdim(three, schedule, 1, 800, {0, 1, 2}, options);
  auto b = SampleDdim(averaged, schedule, 1, 800, {0}, options);
  ASSERT_TRUE(a.ok() && b.ok());
  for (int j = 0; j < 800; ++j) ASSERT_NEAR((*a)[0][j], (*b)[0][j], 1e-5);
}

TEST(Ddim, GuidanceMovesTheMeanAsTheAnalyticAnswerSays) {
  const NoiseSchedule schedule = NoiseSchedule::ScaledLinear();
  const double mu_u = 0.0, mu_c = 0.2, w = 2.5;
  AnalyticDenoiser denoiser(schedule, {mu_c}, mu_u, 0.5);
  DdimOptions options;
  options.guidance = w;
  const int n = 20000;
  auto x = SampleDdim(denoiser, schedule, 1, n, {0}, options);
  ASSERT_TRUE(x.ok());
  const Moments exact = ExactDdimMoments(schedule, options, mu_u + w * (mu_c - mu_u), 0.5);
  const Sampled got = SampleMoments((*x)[0]);
  EXPECT_NEAR(got.mean, exact.mean, 5 * std::sqrt(exact.variance / n));
  EXPECT_NEAR(exact.mean, 0.5, 0.01);
}

TEST(Ddim, DeterministicForASeedAndHookedAfterEveryStep) {
  const NoiseSchedule schedule = NoiseSchedule::ScaledLinear();
  AnalyticDenoiser denoiser(schedule, {0.2}, 0.0, 0.5);
  DdimOptions options;
  options.seed = 7;
  std::vector<int> seen;
  auto hook = [&](int step, int timestep, std::vector<std::vector<float>>* latents) {
    seen.push_back(timestep);
    EXPECT_EQ(latents->size(), 3u);
    if (step == 49) (*latents)[1].assign(10, 0.25f);  // a replacement sticks
    return absl::OkStatus();
  };
  auto a = SampleDdim(denoiser, schedule, 3, 10, {0}, options, hook);
  auto b = SampleDdim(denoiser, schedule, 3, 10, {0}, options);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ((*a)[0], (*b)[0]);
  EXPECT_EQ((*a)[1], std::vector<float>(10, 0.25f));
  ASSERT_EQ(seen.size(), 50u);
  EXPECT_EQ(seen.front(), 960);
  EXPECT_EQ(seen.back(), -1);
  auto stop = [](int step, int, std::vector<std::vector<float>>*) {
    return step == 3 ? absl::CancelledError("stop") : absl::OkStatus();
  };
  EXPECT_EQ(SampleDdim(denoiser, schedule, 1, 4, {0}, options, stop).status().code(),
            absl::StatusCode::kCancelled);
}

// A denoiser answering wrong: the sampler names what and where.
class BadDenoiser : public Denoiser {
 public:
  explicit BadDenoiser(int mode) : mode_(mode) {}
  absl::StatusOr<std::vector<float>> PredictNoise(const NoiseQuery& q) const override {
    if (mode_ == 0) return std::vector<float>(q.latent->size() + 1, 0.0f);
    if (mode_ == 1) return std::vector<float>(q.latent->size(), std::nanf(""));
    return absl::DeadlineExceededError("denoiser timed out");
  }

 private:
  int mode_;
};

TEST(Ddim, BadDenoiserAnswersFailWithWhatAndWhere) {
  const NoiseSchedule schedule = NoiseSchedule::ScaledLinear();
  auto wrong_size = SampleDdim(BadDenoiser(0), schedule, 2, 8, {3}, DdimOptions{});
  EXPECT_EQ(wrong_size.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(wrong_size.status().message().find("target 0, condition 3, timestep 980: 9 values"),
            std::string::npos)
      << wrong_size.status();
  auto nan = SampleDdim(BadDenoiser(1), schedule, 2, 8, {3}, DdimOptions{});
  EXPECT_NE(nan.status().message().find("not finite"), std::string::npos);
  EXPECT_EQ(SampleDdim(BadDenoiser(2), schedule, 2, 8, {3}, DdimOptions{}).status().code(),
            absl::StatusCode::kDeadlineExceeded);
  AnalyticDenoiser fine(schedule, {0.0}, 0.0, 1.0);
  EXPECT_EQ(SampleDdim(fine, schedule, 1, 8, {}, DdimOptions{}).status().code(),
            absl::StatusCode::kInvalidArgument);
  DdimOptions too_many;
  too_many.steps = 1001;
  EXPECT_EQ(SampleDdim(fine, schedule, 1, 8, {0}, too_many).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace instascene::generation::diffusion
