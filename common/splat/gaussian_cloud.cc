#include "common/splat/gaussian_cloud.h"

#include <algorithm>
#include <charconv>
#include <cmath>

#include <Eigen/Core>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "common/geometry/rigid.h"

namespace instascene {
namespace {

absl::Status CheckFinite(const std::vector<float>& values, int per_gaussian,
                         absl::string_view what) {
  for (size_t i = 0; i < values.size(); ++i) {
    if (!std::isfinite(values[i])) {
      return absl::InvalidArgumentError(absl::StrCat("Gaussian #", i / per_gaussian, ": ", what,
                                                     " is ", values[i], " (NaN or Inf)"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

void GaussianCloud::Resize(size_t n) {
  positions.assign(3 * n, 0.0f);
  log_scales.assign(num_scales * n, 0.0f);
  rotations.assign(4 * n, 0.0f);
  for (size_t i = 0; i < n; ++i) rotations[4 * i] = 1.0f;
  opacity_logits.assign(n, 0.0f);
  sh.assign(static_cast<size_t>(sh_stride()) * n, 0.0f);
  for (ExtraChannel& e : extras) e.values.assign(n, 0.0f);
}

absl::Status GaussianCloud::Validate() const {
  const size_t n = size();
  if (num_scales != 2 && num_scales != 3) {
    return absl::InvalidArgumentError(absl::StrCat("num_scales is ", num_scales, ", not 2 or 3"));
  }
  if (sh_degree < 0 || sh_degree > 3) {
    return absl::InvalidArgumentError(absl::StrCat("SH degree ", sh_degree, " outside 0..3"));
  }
  if (positions.size() != 3 * n || log_scales.size() != num_scales * n ||
      rotations.size() != 4 * n || sh.size() != static_cast<size_t>(sh_stride()) * n) {
    return absl::InvalidArgumentError(
        absl::StrCat("attribute arrays disagree on the count of ", n, " Gaussians"));
  }
  if (auto s = CheckFinite(positions, 3, "position"); !s.ok()) return s;
  if (auto s = CheckFinite(log_scales, num_scales, "log-scale"); !s.ok()) return s;
  if (auto s = CheckFinite(rotations, 4, "rotation"); !s.ok()) return s;
  if (auto s = CheckFinite(opacity_logits, 1, "opacity logit"); !s.ok()) return s;
  if (auto s = CheckFinite(sh, sh_stride(), "SH coefficient"); !s.ok()) return s;
  for (size_t i = 0; i < n; ++i) {
    const float* q = &rotations[4 * i];
    if (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3] < 1e-20f) {
      return absl::InvalidArgumentError(absl::StrCat("Gaussian #", i, ": zero-norm quaternion"));
    }
  }
  for (const ExtraChannel& e : extras) {
    if (e.values.size() != n) {
      return absl::InvalidArgumentError(absl::StrCat(
          "extra channel '", e.name, "' has ", e.values.size(), " values for ", n, " Gaussians"));
    }
    if (auto s = CheckFinite(e.values, 1, absl::StrCat("extra '", e.name, "'")); !s.ok()) return s;
  }
  return absl::OkStatus();
}

const ExtraChannel* GaussianCloud::FindExtra(absl::string_view name) const {
  for (const ExtraChannel& e : extras) {
    if (e.name == name) return &e;
  }
  return nullptr;
}

ExtraChannel* GaussianCloud::FindExtra(absl::string_view name) {
  for (ExtraChannel& e : extras) {
    if (e.name == name) return &e;
  }
  return nullptr;
}

void GaussianCloud::SetExtra(std::string name, ScalarType type, std::vector<float> values) {
  if (ExtraChannel* e = FindExtra(name)) {
    e->type = type;
    e->values = std::move(values);
    return;
  }
  extras.push_back({std::move(name), type, std::move(values)});
}

absl::StatusOr<std::vector<float>> GaussianCloud::GatherExtraGroup(absl::string_view prefix,
                                                                   int* dim) const {
  int max_index = -1;
  int count = 0;
  for (const ExtraChannel& e : extras) {
    if (!absl::StartsWith(e.name, prefix)) continue;
    absl::string_view suffix = absl::string_view(e.name).substr(prefix.size());
    int index = 0;
    auto r = std::from_chars(suffix.data(), suffix.data() + suffix.size(), index);
    if (r.ec != std::errc() || r.ptr != suffix.data() + suffix.size()) continue;
    max_index = std::max(max_index, index);
    ++count;
  }
  if (count != max_index + 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("extra channels '", prefix, "*' are not numbered 0..", max_index));
  }
  *dim = count;
  const size_t n = size();
  std::vector<float> out(n * count);
  for (int d = 0; d < count; ++d) {
    const ExtraChannel* e = FindExtra(absl::StrCat(prefix, d));
    for (size_t i = 0; i < n; ++i) out[i * count + d] = e->values[i];
  }
  return out;
}

void GaussianCloud::SetExtraGroup(absl::string_view prefix, int dim,
                                  const std::vector<float>& values) {
  const size_t n = size();
  for (int d = 0; d < dim; ++d) {
    std::vector<float> column(n);
    for (size_t i = 0; i < n; ++i) column[i] = values[i * dim + d];
    SetExtra(absl::StrCat(prefix, d), ScalarType::kFloat32, std::move(column));
  }
}

GaussianCloud GaussianCloud::Subset(const std::vector<uint32_t>& indices) const {
  GaussianCloud out;
  out.num_scales = num_scales;
  out.sh_degree = sh_degree;
  for (const ExtraChannel& e : extras) out.extras.push_back({e.name, e.type, {}});
  out.Resize(indices.size());
  const int stride = sh_stride();
  for (size_t j = 0; j < indices.size(); ++j) {
    const size_t i = indices[j];
    std::copy_n(&positions[3 * i], 3, &out.positions[3 * j]);
    std::copy_n(&log_scales[num_scales * i], num_scales, &out.log_scales[num_scales * j]);
    std::copy_n(&rotations[4 * i], 4, &out.rotations[4 * j]);
    out.opacity_logits[j] = opacity_logits[i];
    std::copy_n(&sh[stride * i], stride, &out.sh[stride * j]);
    for (size_t e = 0; e < extras.size(); ++e) out.extras[e].values[j] = extras[e].values[i];
  }
  return out;
}

Eigen::AlignedBox3f RobustBounds(const GaussianCloud& cloud, double low_fraction,
                                 double high_fraction) {
  Eigen::AlignedBox3f box;
  const size_t n = cloud.size();
  if (n == 0) return box;
  const size_t lo = std::min(n - 1, static_cast<size_t>(low_fraction * static_cast<double>(n)));
  const size_t hi = std::min(n - 1, static_cast<size_t>(high_fraction * static_cast<double>(n)));
  std::vector<float> v(n);
  for (int a = 0; a < 3; ++a) {
    for (size_t i = 0; i < n; ++i) v[i] = cloud.positions[3 * i + a];
    std::nth_element(v.begin(), v.begin() + lo, v.end());
    box.min()[a] = v[lo];
    std::nth_element(v.begin(), v.begin() + hi, v.end());
    box.max()[a] = v[hi];
  }
  return box;
}

GaussianCloud ToSurfels(const GaussianCloud& cloud) {
  if (cloud.num_scales == 2) return cloud;
  GaussianCloud out = cloud;
  out.num_scales = 2;
  const size_t n = cloud.size();
  out.log_scales.resize(2 * n);
  for (size_t i = 0; i < n; ++i) {
    const float* s = &cloud.log_scales[3 * i];
    const float* q = &cloud.rotations[4 * i];
    const int k = static_cast<int>(std::min_element(s, s + 3) - s);  // smallest axis = normal
    const int a = (k + 1) % 3;                                       // cyclic order keeps det +1
    const int b = (k + 2) % 3;
    const Eigen::Matrix3d r = RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]);
    Eigen::Matrix3d surfel;
    surfel << r.col(a), r.col(b), r.col(k);
    const Eigen::Vector4d wxyz = QuaternionWxyzFromRotation(surfel);
    for (int c = 0; c < 4; ++c) out.rotations[4 * i + c] = static_cast<float>(wxyz[c]);
    out.log_scales[2 * i] = s[a];
    out.log_scales[2 * i + 1] = s[b];
  }
  return out;
}

}  // namespace instascene
