// common/splat/gaussian_ply.h: GaussianCloud <-> PLY in the Inria / 2DGS layout (ALGORITHM.md 2.8).
//
// Reading looks every property up by name, in any order, any scalar type, ASCII or binary of either
// endianness. Required: x y z, f_dc_0..2, opacity, scale_0 scale_1 [scale_2], rot_0..3. The SH
// degree follows from the count of f_rest_* (0, 9, 24 or 45, channel-major on disk). nx ny nz are
// dropped (always zero in 3DGS/2DGS files); every other property is kept as an extra channel and
// written back. Opacity logits of +-inf load as OpacityLogit says. A 3-scale file whose scale_2 is
// the 2DGS export's constant log(1e-6) on every Gaussian loads as a 2-scale surfel cloud. Other
// splat formats (compressed PLY, .splat, .spz): splat_formats.h. Stateless, thread-safe.
#pragma once

#include <string>
#include "absl/strings/string_view.h"

#include "absl/status/statusor.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene {

// Opacity logits of +inf / -inf, as splat-transform writes them for fully opaque / fully
// transparent splats (its decompressed alpha of exactly 1 or 0), load as what they mean: the logit
// kOpaqueLogit (sigmoid = 1 in float arithmetic) or its negative (opacity 2e-9). NaN stays an
// error.
inline constexpr float kOpaqueLogit = 20.0f;
float OpacityLogit(float logit);

struct GaussianPlyOptions {
  size_t max_file_bytes = size_t{8} << 30;  // refuse larger files, bytes
};

absl::StatusOr<GaussianCloud> ParseGaussianPly(absl::string_view data, absl::string_view source);
absl::StatusOr<GaussianCloud> ReadGaussianPly(const std::string& path,
                                              const GaussianPlyOptions& options = {});

// Binary little-endian Inria layout: x y z nx ny nz f_dc_0..2 f_rest_* opacity scale_* rot_0..3,
// then the extra channels with their types.
std::string EncodeGaussianPly(const GaussianCloud& cloud);
// Validates, encodes and writes atomically (temp file + fsync + rename).
absl::Status WriteGaussianPly(const std::string& path, const GaussianCloud& cloud);

}  // namespace instascene
