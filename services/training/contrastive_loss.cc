#include "services/training/contrastive_loss.h"

#include <algorithm>
#include <cmath>
#include <map>

namespace instascene::training {

double ContrastiveLoss(const std::vector<float>& x, int dim, const std::vector<uint32_t>& labels,
                       const ContrastiveLossOptions& options, std::vector<double>* grad) {
  const size_t n = labels.size();
  grad->assign(x.size(), 0.0);
  // Valid samples and classes remapped to 0..K-1 (in label order).
  std::map<uint32_t, int> class_of;
  std::vector<size_t> valid;
  for (size_t j = 0; j < n; ++j) {
    if (labels[j] == 0 && !options.consider_negative) continue;
    class_of.emplace(labels[j], 0);
    valid.push_back(j);
  }
  if (valid.empty() || class_of.size() < 2) return 0.0;  // a single class gives no contrast
  int k = 0;
  for (auto& [label, c] : class_of) c = k++;
  const int K = k;
  std::vector<double> xhat(valid.size() * dim), inv_norm(valid.size());
  std::vector<int> y(valid.size());
  for (size_t s = 0; s < valid.size(); ++s) {
    const float* xs = &x[valid[s] * dim];
    double norm = 0;
    for (int d = 0; d < dim; ++d) norm += double{xs[d]} * xs[d];
    inv_norm[s] = 1.0 / (std::sqrt(norm) + 1e-9);
    for (int d = 0; d < dim; ++d) xhat[s * dim + d] = xs[d] * inv_norm[s];
    y[s] = class_of[labels[valid[s]]];
  }
  // Prototypes and temperatures.
  std::vector<double> u(static_cast<size_t>(K) * dim, 0.0), phi(K, 0.0);
  std::vector<double> count(K, 0.0);
  for (size_t s = 0; s < valid.size(); ++s) {
    count[y[s]] += 1;
    for (int d = 0; d < dim; ++d) u[y[s] * dim + d] += xhat[s * dim + d];
  }
  for (int c = 0; c < K; ++c) {
    for (int d = 0; d < dim; ++d) u[c * dim + d] /= count[c];
  }
  for (size_t s = 0; s < valid.size(); ++s) {
    double dist = 0;
    for (int d = 0; d < dim; ++d) {
      const double diff = xhat[s * dim + d] - u[y[s] * dim + d];
      dist += diff * diff;
    }
    phi[y[s]] += std::sqrt(dist);
  }
  for (int c = 0; c < K; ++c) {
    phi[c] = std::clamp(
        10.0 * phi[c] / (count[c] * std::log(count[c] + options.temperature_lambda)), 0.5, 1.0);
  }
  // Loss and gradients w.r.t. x^ (direct) and u.
  double loss = 0;
  std::vector<double> grad_xhat(xhat.size(), 0.0), grad_u(u.size(), 0.0), logits(K), prob(K);
  for (size_t s = 0; s < valid.size(); ++s) {
    double sum = 0;
    for (int c = 0; c < K; ++c) {
      double dot = 0;
      for (int d = 0; d < dim; ++d) dot += xhat[s * dim + d] * u[c * dim + d];
      logits[c] = dot / phi[c];
      sum += std::exp(logits[c]);
    }
    loss += -logits[y[s]] + std::log(sum + 1e-9);
    for (int c = 0; c < K; ++c) {
      const double g = std::exp(logits[c]) / (sum + 1e-9) - (c == y[s] ? 1.0 : 0.0);  // dL/dlogit
      for (int d = 0; d < dim; ++d) {
        grad_xhat[s * dim + d] += g * u[c * dim + d] / phi[c];
        grad_u[c * dim + d] += g * xhat[s * dim + d] / phi[c];
      }
    }
  }
  // u_c = mean of its samples' x^; then x^ = x / (|x| + 1e-9) with the norm constant.
  for (size_t s = 0; s < valid.size(); ++s) {
    double along = 0;  // x^ . dL/dx^, for the norm's Jacobian
    for (int d = 0; d < dim; ++d) {
      grad_xhat[s * dim + d] += grad_u[y[s] * dim + d] / count[y[s]];
      along += grad_xhat[s * dim + d] * xhat[s * dim + d];
    }
    // d x^_i / d x_j = delta_ij / (|x| + e) - x_i x_j / (|x| (|x| + e)^2) = (delta_ij - x^_i x^_j
    // (|x| + e) / |x|) / (|x| + e)
    const double norm = 1.0 / inv_norm[s] - 1e-9;
    const double scale = options.detach_norm || norm <= 0 ? 0.0 : (1.0 / inv_norm[s]) / norm;
    for (int d = 0; d < dim; ++d) {
      (*grad)[valid[s] * dim + d] =
          (grad_xhat[s * dim + d] - scale * along * xhat[s * dim + d]) * inv_norm[s];
    }
  }
  return loss;
}

}  // namespace instascene::training
