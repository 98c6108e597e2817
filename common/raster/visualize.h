// common/raster/visualize.h: turning render outputs into displayable RGB images (depth colour
// map, normals, alpha, feature PCA). Stateless, thread-safe.
#pragma once

#include <cstdint>
#include <vector>

namespace instascene {

// Depth to a blue (near) -> red (far) ramp between the 2nd and 98th percentile of the depths
// where alpha > 0.5; empty pixels are black. Returns HxWx3.
std::vector<float> ColorizeDepth(const std::vector<float>& depth, const std::vector<float>& alpha);
// World normals (HxWx3, not normalised) to RGB = (n / |n| + 1) / 2; empty pixels black.
std::vector<float> NormalsToRgb(const std::vector<float>& normal);
// One channel replicated to RGB.
std::vector<float> GrayToRgb(const std::vector<float>& gray);
// Integer labels (HxW) to distinct colours (0 = black), by hashing the label.
std::vector<float> LabelsToRgb(const std::vector<uint32_t>& labels);
// HxWxD features projected on their 3 principal components (per-image PCA), mapped to [0, 1].
std::vector<float> FeaturesToRgb(const std::vector<float>& features, int dim);

}  // namespace instascene
