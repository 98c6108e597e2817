// common/eval/metrics.h: segmentation and image metrics (ALGORITHM.md sections 6 and 8).
// Pure functions, thread-safe.
#pragma once

#include <cstdint>
#include <map>
#include <vector>

#include "absl/status/statusor.h"
#include "common/scene/image_io.h"

namespace instascene {

// Intersection over union of two binary masks given as label maps and the label selecting each:
// |a==la & b==lb| / |a==la | b==lb|; 0 when both are empty.
double MaskIou(const std::vector<uint32_t>& a, uint32_t label_a, const std::vector<uint32_t>& b,
               uint32_t label_b);

// Adjusted Rand index of two labelings of the same items (Hubert & Arabie); 1 for identical
// partitions, ~0 for independent ones. Label values are arbitrary ids.
double AdjustedRandIndex(const std::vector<uint32_t>& a, const std::vector<uint32_t>& b);

// Instance matching over Gaussians. Instance 0 is "no instance" on both sides and is ignored.
struct InstanceMatch {
  double precision = 0;      // predicted instances matched to a GT instance at IoU > threshold
  double recall = 0;         // GT instances matched at IoU > threshold
  double mean_best_iou = 0;  // mean over GT instances of the best IoU with any prediction
  int predicted = 0, ground_truth = 0, matched = 0;
  std::map<uint32_t, double> best_iou;  // per GT instance
};
// Each (GT, prediction) pair with IoU > threshold (0.5) is a match; above 0.5 a GT instance can
// match at most one prediction (partitions), so no assignment problem arises.
InstanceMatch MatchInstances(const std::vector<uint32_t>& predicted,
                             const std::vector<uint32_t>& ground_truth, double iou_threshold = 0.5);

// Peak signal-to-noise ratio in dB of images in [0, 1] (same size and channels); +inf if equal.
absl::StatusOr<double> Psnr(const Image& a, const Image& b);
// Mean SSIM over pixels and channels: 11x11 Gaussian window, sigma 1.5, C1 = 0.01^2, C2 = 0.03^2,
// zero padding at the borders (as the 2DGS/3DGS training code's conv2d with padding 5).
absl::StatusOr<double> Ssim(const Image& a, const Image& b);

}  // namespace instascene
