// services/training/contrastive_loss.h: the spatial contrastive loss L_CF (paper Eq. 7;
// ALGORITHM.md 5.2, the exact form of the authors' code) with its exact gradient.
//
// Samples x_j (rendered pixel features or 3D Gaussian features) with integer labels y_j:
//   x^_j = x_j / (|x_j| + 1e-9)       (the norm is treated as a constant, as the code detaches it)
//   u_c  = mean of x^_j over class c  (gradients flow into u_c)
//   phi_c = clip(10 sum_j |x^_j - u_c| / (n_c ln(n_c + 1000)), 0.5, 1)   (no gradient)
//   L = - sum_j log( exp(x^_j . u_{y_j} / phi_{y_j}) / (sum_c exp(x^_j . u_c / phi_c) + 1e-9) )
// A sum over samples, not a mean. Pure functions, thread-safe.
#pragma once

#include <cstdint>
#include <vector>

namespace instascene::training {

struct ContrastiveLossOptions {
  bool consider_negative =
      false;  // label 0 is its own class (else samples with label 0 are ignored)
  double temperature_lambda = 1000.0;  // ln(n_c + lambda) in the temperature
  bool detach_norm = true;  // as the authors' code; false = the true gradient through |x| (tests)
};

// Returns the loss and writes dL/dx (same layout as x: samples x dim, row-major) into grad.
double ContrastiveLoss(const std::vector<float>& x, int dim, const std::vector<uint32_t>& labels,
                       const ContrastiveLossOptions& options, std::vector<double>* grad);

}  // namespace instascene::training
