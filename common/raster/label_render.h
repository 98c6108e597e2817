// common/raster/label_render.h: per-pixel instance labels from per-Gaussian labels.
//
// A pixel's label is the label with the largest summed blending weight among the Gaussians that
// make the pixel (0 where alpha < min_alpha). Used for ground-truth masks of synthetic scenes, for
// rendering a result's labels and for label-based click evaluation. Stateless, thread-safe.
#pragma once

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/raster/render_types.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene {

// From a render with a full contributor trace (min_weight 0, all pixels).
std::vector<uint32_t> LabelMapFromTrace(const RenderResult& traced,
                                        const std::vector<uint32_t>& labels,
                                        float min_alpha = 0.5f);

// Renders the cloud (2DGS/3DGS as its scale count says) and returns the W*H label map.
absl::StatusOr<std::vector<uint32_t>> RenderLabelMap(const GaussianCloud& cloud,
                                                     const PinholeCamera& camera,
                                                     const std::vector<uint32_t>& labels,
                                                     float min_alpha = 0.5f, int num_threads = 0);

}  // namespace instascene
