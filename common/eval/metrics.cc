#include "common/eval/metrics.h"

#include <cmath>
#include <limits>
#include <unordered_map>

#include "absl/strings/str_cat.h"

namespace instascene {
namespace {

double Choose2(double n) { return n * (n - 1.0) / 2.0; }

absl::Status SameShape(const Image& a, const Image& b) {
  if (a.width != b.width || a.height != b.height || a.channels != b.channels || a.pixels.empty() ||
      a.pixels.size() != b.pixels.size()) {
    return absl::InvalidArgumentError(absl::StrCat("images differ in size: ", a.width, "x",
                                                   a.height, "x", a.channels, " vs ", b.width, "x",
                                                   b.height, "x", b.channels));
  }
  return absl::OkStatus();
}

// Separable 11-tap Gaussian blur of one channel with zero padding.
std::vector<double> Blur(const std::vector<double>& in, int w, int h) {
  constexpr int kRadius = 5;
  double kernel[2 * kRadius + 1];
  double sum = 0;
  for (int i = -kRadius; i <= kRadius; ++i)
    sum += kernel[i + kRadius] = std::exp(-(i * i) / (2.0 * 1.5 * 1.5));
  for (double& k : kernel) k /= sum;
  std::vector<double> tmp(in.size(), 0.0), out(in.size(), 0.0);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      double v = 0;
      for (int k = -kRadius; k <= kRadius; ++k) {
        if (x + k >= 0 && x + k < w)
          v += kernel[k + kRadius] * in[static_cast<size_t>(y) * w + x + k];
      }
      tmp[static_cast<size_t>(y) * w + x] = v;
    }
  }
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      double v = 0;
      for (int k = -kRadius; k <= kRadius; ++k) {
        if (y + k >= 0 && y + k < h)
          v += kernel[k + kRadius] * tmp[static_cast<size_t>(y + k) * w + x];
      }
      out[static_cast<size_t>(y) * w + x] = v;
    }
  }
  return out;
}

}  // namespace

double MaskIou(const std::vector<uint32_t>& a, uint32_t label_a, const std::vector<uint32_t>& b,
               uint32_t label_b) {
  size_t inter = 0, uni = 0;
  for (size_t i = 0; i < a.size() && i < b.size(); ++i) {
    const bool in_a = a[i] == label_a, in_b = b[i] == label_b;
    inter += in_a && in_b;
    uni += in_a || in_b;
  }
  return uni == 0 ? 0.0 : static_cast<double>(inter) / static_cast<double>(uni);
}

double AdjustedRandIndex(const std::vector<uint32_t>& a, const std::vector<uint32_t>& b) {
  const size_t n = std::min(a.size(), b.size());
  if (n < 2) return 1.0;
  std::unordered_map<uint64_t, double> joint;
  std::unordered_map<uint32_t, double> rows, cols;
  for (size_t i = 0; i < n; ++i) {
    joint[(uint64_t{a[i]} << 32) | b[i]] += 1;
    rows[a[i]] += 1;
    cols[b[i]] += 1;
  }
  double index = 0, sum_rows = 0, sum_cols = 0;
  for (const auto& [key, count] : joint) index += Choose2(count);
  for (const auto& [key, count] : rows) sum_rows += Choose2(count);
  for (const auto& [key, count] : cols) sum_cols += Choose2(count);
  const double expected = sum_rows * sum_cols / Choose2(static_cast<double>(n));
  const double max_index = 0.5 * (sum_rows + sum_cols);
  if (max_index == expected)
    return 1.0;  // both partitions trivial (all one cluster or all singletons)
  return (index - expected) / (max_index - expected);
}

InstanceMatch MatchInstances(const std::vector<uint32_t>& predicted,
                             const std::vector<uint32_t>& ground_truth, double iou_threshold) {
  InstanceMatch m;
  std::unordered_map<uint32_t, double> pred_size, gt_size;
  std::unordered_map<uint64_t, double> overlap;
  const size_t n = std::min(predicted.size(), ground_truth.size());
  for (size_t i = 0; i < n; ++i) {
    if (predicted[i] != 0) pred_size[predicted[i]] += 1;
    if (ground_truth[i] != 0) gt_size[ground_truth[i]] += 1;
    if (predicted[i] != 0 && ground_truth[i] != 0)
      overlap[(uint64_t{ground_truth[i]} << 32) | predicted[i]] += 1;
  }
  m.predicted = static_cast<int>(pred_size.size());
  m.ground_truth = static_cast<int>(gt_size.size());
  for (const auto& [id, size] : gt_size) m.best_iou[id] = 0.0;
  std::unordered_map<uint32_t, bool> pred_matched;
  for (const auto& [key, inter] : overlap) {
    const uint32_t g = static_cast<uint32_t>(key >> 32),
                   p = static_cast<uint32_t>(key & 0xffffffffu);
    const double iou = inter / (gt_size[g] + pred_size[p] - inter);
    m.best_iou[g] = std::max(m.best_iou[g], iou);
    if (iou > iou_threshold) pred_matched[p] = true;
  }
  double sum = 0;
  for (const auto& [id, iou] : m.best_iou) {
    sum += iou;
    m.matched += iou > iou_threshold;
  }
  m.mean_best_iou = m.ground_truth > 0 ? sum / m.ground_truth : 0.0;
  m.recall = m.ground_truth > 0 ? static_cast<double>(m.matched) / m.ground_truth : 0.0;
  m.precision = m.predicted > 0 ? static_cast<double>(pred_matched.size()) / m.predicted : 0.0;
  return m;
}

absl::StatusOr<double> Psnr(const Image& a, const Image& b) {
  if (absl::Status s = SameShape(a, b); !s.ok()) return s;
  double mse = 0;
  for (size_t i = 0; i < a.pixels.size(); ++i) {
    const double d = static_cast<double>(a.pixels[i]) - b.pixels[i];
    mse += d * d;
  }
  mse /= static_cast<double>(a.pixels.size());
  if (mse == 0) return std::numeric_limits<double>::infinity();
  return -10.0 * std::log10(mse);
}

absl::StatusOr<double> Ssim(const Image& a, const Image& b) {
  if (absl::Status s = SameShape(a, b); !s.ok()) return s;
  constexpr double kC1 = 0.01 * 0.01, kC2 = 0.03 * 0.03;
  const int w = a.width, h = a.height, c = a.channels;
  const size_t n = static_cast<size_t>(w) * h;
  double total = 0;
  for (int ch = 0; ch < c; ++ch) {
    std::vector<double> x(n), y(n), xx(n), yy(n), xy(n);
    for (size_t i = 0; i < n; ++i) {
      x[i] = a.pixels[i * c + ch];
      y[i] = b.pixels[i * c + ch];
      xx[i] = x[i] * x[i];
      yy[i] = y[i] * y[i];
      xy[i] = x[i] * y[i];
    }
    const std::vector<double> mx = Blur(x, w, h), my = Blur(y, w, h);
    const std::vector<double> sxx = Blur(xx, w, h), syy = Blur(yy, w, h), sxy = Blur(xy, w, h);
    for (size_t i = 0; i < n; ++i) {
      const double vx = sxx[i] - mx[i] * mx[i], vy = syy[i] - my[i] * my[i],
                   cxy = sxy[i] - mx[i] * my[i];
      total += ((2 * mx[i] * my[i] + kC1) * (2 * cxy + kC2)) /
               ((mx[i] * mx[i] + my[i] * my[i] + kC1) * (vx + vy + kC2));
    }
  }
  return total / static_cast<double>(n * c);
}

}  // namespace instascene
