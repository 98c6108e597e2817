#include "common/raster/visualize.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Dense>

namespace instascene {

std::vector<float> ColorizeDepth(const std::vector<float>& depth, const std::vector<float>& alpha) {
  std::vector<float> valid;
  for (size_t i = 0; i < depth.size(); ++i) {
    if (alpha[i] > 0.5f) valid.push_back(depth[i]);
  }
  std::vector<float> rgb(3 * depth.size(), 0.0f);
  if (valid.empty()) return rgb;
  std::sort(valid.begin(), valid.end());
  const float lo = valid[valid.size() * 2 / 100], hi = valid[valid.size() * 98 / 100];
  const float range = std::max(hi - lo, 1e-6f);
  for (size_t i = 0; i < depth.size(); ++i) {
    if (alpha[i] <= 0.5f) continue;
    const float t = std::clamp((depth[i] - lo) / range, 0.0f, 1.0f);
    rgb[3 * i] = std::clamp(1.5f - std::abs(4.0f * t - 3.0f), 0.0f, 1.0f);
    rgb[3 * i + 1] = std::clamp(1.5f - std::abs(4.0f * t - 2.0f), 0.0f, 1.0f);
    rgb[3 * i + 2] = std::clamp(1.5f - std::abs(4.0f * t - 1.0f), 0.0f, 1.0f);
  }
  return rgb;
}

std::vector<float> NormalsToRgb(const std::vector<float>& normal) {
  std::vector<float> rgb(normal.size(), 0.0f);
  for (size_t i = 0; i + 2 < normal.size(); i += 3) {
    const float n = std::sqrt(normal[i] * normal[i] + normal[i + 1] * normal[i + 1] +
                              normal[i + 2] * normal[i + 2]);
    if (n < 1e-6f) continue;
    for (int c = 0; c < 3; ++c) rgb[i + c] = 0.5f * (normal[i + c] / n + 1.0f);
  }
  return rgb;
}

std::vector<float> GrayToRgb(const std::vector<float>& gray) {
  std::vector<float> rgb(3 * gray.size());
  for (size_t i = 0; i < gray.size(); ++i) rgb[3 * i] = rgb[3 * i + 1] = rgb[3 * i + 2] = gray[i];
  return rgb;
}

std::vector<float> LabelsToRgb(const std::vector<uint32_t>& labels) {
  std::vector<float> rgb(3 * labels.size(), 0.0f);
  for (size_t i = 0; i < labels.size(); ++i) {
    if (labels[i] == 0) continue;
    uint32_t h = labels[i] * 2654435761u;
    h ^= h >> 15;
    for (int c = 0; c < 3; ++c)
      rgb[3 * i + c] = 0.25f + 0.75f * static_cast<float>((h >> (8 * c)) & 0xff) / 255.0f;
  }
  return rgb;
}

std::vector<float> FeaturesToRgb(const std::vector<float>& features, int dim) {
  const size_t n = dim > 0 ? features.size() / dim : 0;
  std::vector<float> rgb(3 * n, 0.0f);
  if (n == 0) return rgb;
  Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> f(
      features.data(), n, dim);
  const Eigen::RowVectorXd mean = f.cast<double>().colwise().mean();
  const Eigen::MatrixXd centered = f.cast<double>().rowwise() - mean;
  const Eigen::MatrixXd cov = centered.transpose() * centered / static_cast<double>(n);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(cov);
  const int k = std::min(dim, 3);
  const Eigen::MatrixXd basis = eig.eigenvectors().rightCols(k);  // largest eigenvalues last
  const Eigen::MatrixXd proj = centered * basis;
  for (int c = 0; c < k; ++c) {
    const double lo = proj.col(c).minCoeff(), hi = proj.col(c).maxCoeff();
    for (size_t i = 0; i < n; ++i)
      rgb[3 * i + c] = static_cast<float>((proj(i, c) - lo) / std::max(hi - lo, 1e-12));
  }
  return rgb;
}

}  // namespace instascene
