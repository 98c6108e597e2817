// common/core/statistics.h: small order statistics used by benchmarks and metrics.
#pragma once

#include <algorithm>
#include <vector>

namespace instascene {

// Median of the values (mean of the two middle values for an even count); 0 for an empty input.
inline double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  double upper = values[mid];
  if (values.size() % 2 == 1) return upper;
  double lower = *std::max_element(values.begin(), values.begin() + mid);
  return 0.5 * (lower + upper);
}

}  // namespace instascene
