#include "services/training/contrastive_loss.h"

#include <algorithm>
#include <cmath>
#include <map>

namespace instascene::training {
namespace {

// The valid samples (index into the input), their classes remapped to 0..K-1 (in label order),
// their normalised features and inverse norms.
struct Batch {
  std::vector<size_t> valid;
  std::vector<int> y;
  std::vector<double> xhat, inv_norm;
  int K = 0;
};

Batch NormalizedBatch(const std::vector<float>& x, int dim, const std::vector<uint32_t>& labels,
                      bool consider_negative) {
  Batch b;
  std::map<uint32_t, int> class_of;
  for (size_t j = 0; j < labels.size(); ++j) {
    if (labels[j] == 0 && !consider_negative) continue;
    class_of.emplace(labels[j], 0);
    b.valid.push_back(j);
  }
  for (auto& [label, c] : class_of) c = b.K++;
  b.xhat.resize(b.valid.size() * dim);
  b.inv_norm.resize(b.valid.size());
  b.y.resize(b.valid.size());
  for (size_t s = 0; s < b.valid.size(); ++s) {
    const float* xs = &x[b.valid[s] * dim];
    double norm = 0;
    for (int d = 0; d < dim; ++d) norm += double{xs[d]} * xs[d];
    b.inv_norm[s] = 1.0 / (std::sqrt(norm) + 1e-9);
    for (int d = 0; d < dim; ++d) b.xhat[s * dim + d] = xs[d] * b.inv_norm[s];
    b.y[s] = class_of[labels[b.valid[s]]];
  }
  return b;
}

// Per class: its prototype u_c (the mean of its samples' x^), its count and its temperature
// phi_c = clip(10 sum |x^ - u_c| / (n_c ln(n_c + lambda)), 0.5, 1).
struct Prototypes {
  std::vector<double> u, phi, count;
};

Prototypes ClassPrototypes(const Batch& b, int dim, double temperature_lambda) {
  Prototypes p;
  p.u.assign(static_cast<size_t>(b.K) * dim, 0.0);
  p.phi.assign(b.K, 0.0);
  p.count.assign(b.K, 0.0);
  for (size_t s = 0; s < b.valid.size(); ++s) {
    p.count[b.y[s]] += 1;
    for (int d = 0; d < dim; ++d) p.u[b.y[s] * dim + d] += b.xhat[s * dim + d];
  }
  for (int c = 0; c < b.K; ++c) {
    for (int d = 0; d < dim; ++d) p.u[c * dim + d] /= p.count[c];
  }
  for (size_t s = 0; s < b.valid.size(); ++s) {
    double dist = 0;
    for (int d = 0; d < dim; ++d) {
      const double diff = b.xhat[s * dim + d] - p.u[b.y[s] * dim + d];
      dist += diff * diff;
    }
    p.phi[b.y[s]] += std::sqrt(dist);
  }
  for (int c = 0; c < b.K; ++c) {
    p.phi[c] = std::clamp(
        10.0 * p.phi[c] / (p.count[c] * std::log(p.count[c] + temperature_lambda)), 0.5, 1.0);
  }
  return p;
}

// The loss (a sum over samples) and its gradients with respect to x^ (direct) and u.
double SoftmaxLoss(const Batch& b, int dim, const Prototypes& p, std::vector<double>* grad_xhat,
                   std::vector<double>* grad_u) {
  double loss = 0;
  grad_xhat->assign(b.xhat.size(), 0.0);
  grad_u->assign(p.u.size(), 0.0);
  std::vector<double> logits(b.K);
  for (size_t s = 0; s < b.valid.size(); ++s) {
    double sum = 0;
    for (int c = 0; c < b.K; ++c) {
      double dot = 0;
      for (int d = 0; d < dim; ++d) dot += b.xhat[s * dim + d] * p.u[c * dim + d];
      logits[c] = dot / p.phi[c];
      sum += std::exp(logits[c]);
    }
    loss += -logits[b.y[s]] + std::log(sum + 1e-9);
    for (int c = 0; c < b.K; ++c) {
      const double g = std::exp(logits[c]) / (sum + 1e-9) - (c == b.y[s] ? 1.0 : 0.0);  // dL/dlogit
      for (int d = 0; d < dim; ++d) {
        (*grad_xhat)[s * dim + d] += g * p.u[c * dim + d] / p.phi[c];
        (*grad_u)[c * dim + d] += g * b.xhat[s * dim + d] / p.phi[c];
      }
    }
  }
  return loss;
}

}  // namespace

double ContrastiveLoss(const std::vector<float>& x, int dim, const std::vector<uint32_t>& labels,
                       const ContrastiveLossOptions& options, std::vector<double>* grad) {
  grad->assign(x.size(), 0.0);
  const Batch b = NormalizedBatch(x, dim, labels, options.consider_negative);
  if (b.valid.empty() || b.K < 2) return 0.0;  // a single class gives no contrast
  const Prototypes p = ClassPrototypes(b, dim, options.temperature_lambda);
  std::vector<double> grad_xhat, grad_u;
  const double loss = SoftmaxLoss(b, dim, p, &grad_xhat, &grad_u);
  // u_c = mean of its samples' x^; then x^ = x / (|x| + 1e-9) with the norm constant.
  for (size_t s = 0; s < b.valid.size(); ++s) {
    double along = 0;  // x^ . dL/dx^, for the norm's Jacobian
    for (int d = 0; d < dim; ++d) {
      grad_xhat[s * dim + d] += grad_u[b.y[s] * dim + d] / p.count[b.y[s]];
      along += grad_xhat[s * dim + d] * b.xhat[s * dim + d];
    }
    // d x^_i / d x_j = delta_ij / (|x| + e) - x_i x_j / (|x| (|x| + e)^2) = (delta_ij - x^_i x^_j
    // (|x| + e) / |x|) / (|x| + e)
    const double norm = 1.0 / b.inv_norm[s] - 1e-9;
    const double scale = options.detach_norm || norm <= 0 ? 0.0 : (1.0 / b.inv_norm[s]) / norm;
    for (int d = 0; d < dim; ++d) {
      (*grad)[b.valid[s] * dim + d] =
          (grad_xhat[s * dim + d] - scale * along * b.xhat[s * dim + d]) * b.inv_norm[s];
    }
  }
  return loss;
}

}  // namespace instascene::training
