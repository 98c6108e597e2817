#include "common/splat/gaussian_ply.h"

#include <charconv>
#include <cmath>
#include <limits>
#include <set>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene {
namespace {

// log(1e-6) written by 2DGS exports in the unused third scale slot (ALGORITHM.md 2.8).
constexpr float kSurfelThirdLogScale = -13.815510557964274f;

// Returns the numeric suffix of `name` after `prefix` (canonical decimal: "rot_00" is not rot_0),
// or -1.
int IndexedSuffix(absl::string_view name, absl::string_view prefix) {
  if (!absl::StartsWith(name, prefix)) return -1;
  absl::string_view rest = name.substr(prefix.size());
  if (rest.size() > 1 && rest[0] == '0') return -1;  // found by ply_fuzz
  int index = -1;
  auto r = std::from_chars(rest.data(), rest.data() + rest.size(), index);
  if (r.ec != std::errc() || r.ptr != rest.data() + rest.size() || rest.empty()) return -1;
  return index;
}

bool IsCoreProperty(absl::string_view name) {
  static const std::set<absl::string_view> kCore = {"x", "y", "z", "nx", "ny", "nz", "opacity"};
  return kCore.count(name) > 0 || IndexedSuffix(name, "f_dc_") >= 0 ||
         IndexedSuffix(name, "f_rest_") >= 0 || IndexedSuffix(name, "scale_") >= 0 ||
         IndexedSuffix(name, "rot_") >= 0;
}

// The columns of a Gaussian PLY's vertex element: every core property under its canonical name,
// indexed groups numbered 0..n-1, counts that make an SH degree 0-3, 2 or 3 scales, a quaternion.
struct GaussianColumns {
  int pos[3], dc[3], scale[3], rot[4], opacity;
  std::vector<int> rest;  // f_rest_*, channel-major
  int num_scales, sh_degree;
};
// The column of a required property.
absl::StatusOr<int> RequireColumn(const PlyColumns& cols, const std::string& name,
                                  absl::string_view source) {
  const int c = cols.Find(name);
  if (c < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": missing required vertex property '", name, "'"));
  }
  return c;
}

// How many properties `prefix`<n> there are; they must be numbered 0..count-1.
absl::StatusOr<int> CountGroup(const PlyColumns& cols, absl::string_view prefix,
                               absl::string_view source) {
  int count = 0, max_index = -1;
  for (const std::string& n : cols.names) {
    const int idx = IndexedSuffix(n, prefix);
    if (idx >= 0) {
      ++count;
      max_index = std::max(max_index, idx);
    }
  }
  if (count != max_index + 1) {
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": properties '", prefix, "*' are not numbered 0..", max_index));
  }
  return count;
}

// The group sizes must make an SH degree 0-3, 2 or 3 scales, a quaternion and RGB.
absl::Status CheckGroupSizes(int num_rest, int num_scales, int num_rot, int num_dc,
                             absl::string_view source, int* sh_degree) {
  *sh_degree = -1;
  for (int d = 0; d <= 3; ++d) {
    if (num_rest == 3 * (NumShCoeffs(d) - 1)) *sh_degree = d;
  }
  if (*sh_degree < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        source, ": ", num_rest, " f_rest_* properties; expected 0, 9, 24 or 45 (SH degree 0-3)"));
  }
  if (num_scales != 2 && num_scales != 3) {
    return absl::InvalidArgumentError(absl::StrCat(
        source, ": ", num_scales, " scale_* properties; expected 2 (2DGS) or 3 (3DGS)"));
  }
  if (num_rot != 4) {
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": ", num_rot, " rot_* properties; expected 4 (quaternion w x y z)"));
  }
  if (num_dc != 3) {
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": ", num_dc, " f_dc_* properties; expected 3 (R, G, B)"));
  }
  return absl::OkStatus();
}

absl::StatusOr<GaussianColumns> FindGaussianColumns(const PlyColumns& cols,
                                                    absl::string_view source) {
  auto require = [&](const std::string& name) { return RequireColumn(cols, name, source); };
  GaussianColumns out;
  ASSIGN_OR_RETURN(int num_rest, CountGroup(cols, "f_rest_", source));
  ASSIGN_OR_RETURN(int num_scales, CountGroup(cols, "scale_", source));
  ASSIGN_OR_RETURN(int num_rot, CountGroup(cols, "rot_", source));
  ASSIGN_OR_RETURN(int num_dc, CountGroup(cols, "f_dc_", source));
  RETURN_IF_ERROR(CheckGroupSizes(num_rest, num_scales, num_rot, num_dc, source, &out.sh_degree));
  out.num_scales = num_scales;
  ASSIGN_OR_RETURN(out.pos[0], require("x"));
  ASSIGN_OR_RETURN(out.pos[1], require("y"));
  ASSIGN_OR_RETURN(out.pos[2], require("z"));
  ASSIGN_OR_RETURN(out.opacity, require("opacity"));
  // Every index of each group must be there under its canonical name.
  for (int i = 0; i < 3; ++i) {
    ASSIGN_OR_RETURN(out.dc[i], require(absl::StrCat("f_dc_", i)));
  }
  for (int i = 0; i < num_scales; ++i) {
    ASSIGN_OR_RETURN(out.scale[i], require(absl::StrCat("scale_", i)));
  }
  for (int i = 0; i < 4; ++i) {
    ASSIGN_OR_RETURN(out.rot[i], require(absl::StrCat("rot_", i)));
  }
  out.rest.resize(num_rest);
  for (int i = 0; i < num_rest; ++i) {
    ASSIGN_OR_RETURN(out.rest[i], require(absl::StrCat("f_rest_", i)));
  }
  return out;
}

// 2DGS exports write a constant log(1e-6) third scale: such "ellipsoids" are surfels.
bool SurfelThirdScale(const std::vector<float>& third_log_scale) {
  for (float s : third_log_scale) {
    if (!(std::abs(s - kSurfelThirdLogScale) < 1e-3f)) return false;
  }
  return true;
}

}  // namespace

float OpacityLogit(float logit) {
  if (logit == std::numeric_limits<float>::infinity()) return kOpaqueLogit;
  if (logit == -std::numeric_limits<float>::infinity()) return -kOpaqueLogit;
  return logit;  // NaN stays NaN: Validate refuses it
}

absl::StatusOr<GaussianCloud> ParseGaussianPly(absl::string_view data, absl::string_view source) {
  ASSIGN_OR_RETURN(PlyHeader header, ParsePlyHeader(data, source));
  for (const PlyElement& e : header.elements) {
    if (e.name == "chunk") {
      return absl::InvalidArgumentError(absl::StrCat(
          source,
          ": a SuperSplat compressed PLY (element 'chunk'); ReadSplatFile (splat_formats.h) "
          "reads it"));
    }
  }
  ASSIGN_OR_RETURN(PlyColumns cols, ReadPlyElement(data, header, "vertex", source));
  ASSIGN_OR_RETURN(const GaussianColumns gc, FindGaussianColumns(cols, source));
  const int *pos = gc.pos, *dc = gc.dc, *scale = gc.scale, *rot = gc.rot;
  const std::vector<int>& rest = gc.rest;
  const int opacity = gc.opacity, sh_degree = gc.sh_degree;
  int num_scales = gc.num_scales;
  const size_t n = static_cast<size_t>(cols.count);
  if (num_scales == 3 && n > 0 && SurfelThirdScale(cols.columns[scale[2]])) num_scales = 2;

  GaussianCloud cloud;
  cloud.num_scales = num_scales;
  cloud.sh_degree = sh_degree;
  for (size_t c = 0; c < cols.names.size(); ++c) {
    if (!IsCoreProperty(cols.names[c])) cloud.extras.push_back({cols.names[c], cols.types[c], {}});
  }
  cloud.Resize(n);
  const int coeffs = NumShCoeffs(sh_degree);
  for (size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) cloud.positions[3 * i + a] = cols.columns[pos[a]][i];
    for (int a = 0; a < num_scales; ++a)
      cloud.log_scales[num_scales * i + a] = cols.columns[scale[a]][i];
    for (int a = 0; a < 4; ++a) cloud.rotations[4 * i + a] = cols.columns[rot[a]][i];
    cloud.opacity_logits[i] = OpacityLogit(cols.columns[opacity][i]);
    float* sh = &cloud.sh[static_cast<size_t>(cloud.sh_stride()) * i];
    for (int c = 0; c < 3; ++c) {
      sh[c] = cols.columns[dc[c]][i];
      // Channel-major on disk: f_rest_{c * (coeffs - 1) + k - 1} is coefficient k of channel c.
      for (int k = 1; k < coeffs; ++k)
        sh[3 * k + c] = cols.columns[rest[c * (coeffs - 1) + k - 1]][i];
    }
  }
  for (ExtraChannel& e : cloud.extras) e.values = std::move(cols.columns[cols.Find(e.name)]);
  if (absl::Status s = cloud.Validate(); !s.ok()) return Annotate(s, source);
  return cloud;
}

absl::StatusOr<GaussianCloud> ReadGaussianPly(const std::string& path,
                                              const GaussianPlyOptions& options) {
  ASSIGN_OR_RETURN(std::string data, ReadFileBounded(path, options.max_file_bytes));
  return ParseGaussianPly(data, path);
}

std::string EncodeGaussianPly(const GaussianCloud& cloud) {
  PlyColumns cols;
  const size_t n = cloud.size();
  cols.count = static_cast<int64_t>(n);
  auto add = [&](std::string name, ScalarType type = ScalarType::kFloat32) -> std::vector<float>& {
    cols.names.push_back(std::move(name));
    cols.types.push_back(type);
    cols.columns.emplace_back(n, 0.0f);
    return cols.columns.back();
  };
  const char* kAxes[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    std::vector<float>& col = add(kAxes[a]);
    for (size_t i = 0; i < n; ++i) col[i] = cloud.positions[3 * i + a];
  }
  add("nx");
  add("ny");
  add("nz");
  const int coeffs = NumShCoeffs(cloud.sh_degree);
  const int stride = cloud.sh_stride();
  for (int c = 0; c < 3; ++c) {
    std::vector<float>& col = add(absl::StrCat("f_dc_", c));
    for (size_t i = 0; i < n; ++i) col[i] = cloud.sh[stride * i + c];
  }
  for (int c = 0; c < 3; ++c) {
    for (int k = 1; k < coeffs; ++k) {
      std::vector<float>& col = add(absl::StrCat("f_rest_", c * (coeffs - 1) + k - 1));
      for (size_t i = 0; i < n; ++i) col[i] = cloud.sh[stride * i + 3 * k + c];
    }
  }
  add("opacity") = cloud.opacity_logits;
  for (int a = 0; a < cloud.num_scales; ++a) {
    std::vector<float>& col = add(absl::StrCat("scale_", a));
    for (size_t i = 0; i < n; ++i) col[i] = cloud.log_scales[cloud.num_scales * i + a];
  }
  for (int a = 0; a < 4; ++a) {
    std::vector<float>& col = add(absl::StrCat("rot_", a));
    for (size_t i = 0; i < n; ++i) col[i] = cloud.rotations[4 * i + a];
  }
  for (const ExtraChannel& e : cloud.extras) add(e.name, e.type) = e.values;
  return EncodePlyBinary("vertex", cols, {"written by instascene"});
}

absl::Status WriteGaussianPly(const std::string& path, const GaussianCloud& cloud) {
  RETURN_IF_ERROR(Annotate(cloud.Validate(), path));
  return WriteFileAtomically(path, EncodeGaussianPly(cloud));
}

}  // namespace instascene
