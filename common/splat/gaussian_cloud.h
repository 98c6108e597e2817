// common/splat/gaussian_cloud.h: the Gaussian splat model, as a struct of arrays.
//
// Holds 2DGS surfels (2 log-scales) or 3DGS ellipsoids (3 log-scales), with SH colour of degree 0-3
// and any number of named extra per-Gaussian channels (features, labels, ...). Owns its arrays; a
// const GaussianCloud is safe to read from many threads.
#pragma once

#include <cstdint>
#include <string>
#include <vector>
#include "absl/strings/string_view.h"

#include <Eigen/Geometry>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "common/splat/ply.h"

namespace instascene {

// Number of SH coefficients per colour channel for a degree: (degree + 1)^2.
constexpr int NumShCoeffs(int degree) { return (degree + 1) * (degree + 1); }

// One named per-Gaussian scalar channel, kept through load/save with its PLY type.
struct ExtraChannel {
  std::string name;
  ScalarType type = ScalarType::kFloat32;
  std::vector<float> values;  // one per Gaussian
};

struct GaussianCloud {
  int num_scales = 2;                 // 2 = 2DGS surfel, 3 = 3DGS ellipsoid
  int sh_degree = 0;                  // 0..3
  std::vector<float> positions;       // 3 per Gaussian: x, y, z in world units
  std::vector<float> log_scales;      // num_scales per Gaussian, natural log of the std-dev
  std::vector<float> rotations;       // 4 per Gaussian: quaternion w, x, y, z (not normalised)
  std::vector<float> opacity_logits;  // 1 per Gaussian: opacity = sigmoid(logit)
  std::vector<float> sh;              // NumShCoeffs(sh_degree) * 3 per Gaussian, [coeff][rgb]
  std::vector<ExtraChannel> extras;   // each with one value per Gaussian

  size_t size() const { return opacity_logits.size(); }
  int sh_stride() const { return NumShCoeffs(sh_degree) * 3; }

  // Allocates all arrays for n Gaussians (zero-filled; quaternions set to identity).
  void Resize(size_t n);

  // Checks array sizes, finiteness of every value and non-zero quaternions. The error names the
  // Gaussian index and the attribute.
  absl::Status Validate() const;

  const ExtraChannel* FindExtra(absl::string_view name) const;
  ExtraChannel* FindExtra(absl::string_view name);

  // Adds or replaces an extra channel.
  void SetExtra(std::string name, ScalarType type, std::vector<float> values);

  // Gathers the channels prefix0, prefix1, ... (e.g. "segfeat_") as an N x D row-major matrix;
  // D = 0 when none exist. Fails when the numbering has gaps.
  absl::StatusOr<std::vector<float>> GatherExtraGroup(absl::string_view prefix, int* dim) const;
  // Replaces the channels prefix0..prefix{dim-1} from an N x dim row-major matrix.
  void SetExtraGroup(absl::string_view prefix, int dim, const std::vector<float>& values);

  // The Gaussians at `indices`, in that order, with every attribute and extra channel.
  GaussianCloud Subset(const std::vector<uint32_t>& indices) const;
};

// Per-axis percentile box of the Gaussian centres (default 2nd-98th): robust against the floaters
// real captures carry. Empty box for an empty cloud.
Eigen::AlignedBox3f RobustBounds(const GaussianCloud& cloud, double low_fraction = 0.02,
                                 double high_fraction = 0.98);

// Turns a 3DGS cloud into 2DGS surfels by dropping each Gaussian's smallest axis: the two largest
// axes become the tangent axes and the smallest becomes the normal (rotation re-ordered, kept
// right-handed). A surfel cloud is returned unchanged.
GaussianCloud ToSurfels(const GaussianCloud& cloud);

}  // namespace instascene
