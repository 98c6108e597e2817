#include "common/splat/splat_formats.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/splat/ply.h"
#include "common/splat/splat_decoding.h"

namespace instascene {
namespace {

using splat_decoding::Bad;
using splat_decoding::Gunzip;
using splat_decoding::IsGzip;
using splat_decoding::IsNgsp;
using splat_decoding::kShC0;
using splat_decoding::kSpzMagic;
using splat_decoding::Load;

constexpr size_t kSplatRecord = 32;  // bytes per .splat record

bool IsPly(absl::string_view head) {
  return absl::StartsWith(head, "ply\n") || absl::StartsWith(head, "ply\r\n");
}

// ---- .splat ----

absl::StatusOr<GaussianCloud> ParseDotSplat(absl::string_view data, absl::string_view name) {
  if (data.empty() || data.size() % kSplatRecord != 0)
    return Bad(name, absl::StrCat(".splat: ", data.size(), " bytes, not a positive multiple of ",
                                  kSplatRecord));
  const size_t n = data.size() / kSplatRecord;
  GaussianCloud cloud;
  cloud.num_scales = 3;
  cloud.sh_degree = 0;
  cloud.Resize(n);
  for (size_t i = 0; i < n; ++i) {
    const char* r = data.data() + kSplatRecord * i;
    for (int a = 0; a < 3; ++a) {
      cloud.positions[3 * i + a] = Load<float>(r + 4 * a);
      const float scale = Load<float>(r + 12 + 4 * a);
      if (!(scale > 0) || !std::isfinite(scale))
        return Bad(name, absl::StrCat(".splat: Gaussian ", i, " has scale ", scale));
      cloud.log_scales[3 * i + a] = std::log(scale);
    }
    const auto* b = reinterpret_cast<const uint8_t*>(r + 24);
    for (int a = 0; a < 3; ++a)
      cloud.sh[3 * i + a] = static_cast<float>((b[a] / 255.0 - 0.5) / kShC0);
    // As splat-transform reads it: alpha clamped to [1e-6, 1 - 1e-6].
    const double alpha = std::clamp(b[3] / 255.0, 1e-6, 1 - 1e-6);
    cloud.opacity_logits[i] = static_cast<float>(std::log(alpha / (1 - alpha)));
    double q[4], len = 0;
    for (int a = 0; a < 4; ++a) {
      q[a] = b[4 + a] / 255.0 * 2 - 1;
      len += q[a] * q[a];
    }
    len = std::sqrt(len);
    for (int a = 0; a < 4; ++a)
      cloud.rotations[4 * i + a] =
          len > 0 ? static_cast<float>(q[a] / len) : (a == 0 ? 1.0f : 0.0f);
  }
  if (absl::Status s = cloud.Validate(); !s.ok()) return Bad(name, s.message());
  return cloud;
}

}  // namespace

absl::string_view SplatFormatName(SplatFormat format) {
  switch (format) {
    case SplatFormat::kInriaPly:
      return "ply";
    case SplatFormat::kCompressedPly:
      return "compressed ply";
    case SplatFormat::kSplat:
      return "splat";
    case SplatFormat::kSpz:
      return "spz";
  }
  return "?";
}

absl::StatusOr<SplatFormat> DetectSplatFormat(absl::string_view head, absl::string_view name) {
  if (IsPly(head)) {
    ASSIGN_OR_RETURN(PlyHeader header, ParsePlyHeader(head, name));
    for (const PlyElement& e : header.elements)
      if (e.name == "chunk") return SplatFormat::kCompressedPly;
    return SplatFormat::kInriaPly;
  }
  if (IsGzip(head) || IsNgsp(head)) return SplatFormat::kSpz;
  if (absl::EndsWith(absl::AsciiStrToLower(name), ".splat")) return SplatFormat::kSplat;
  return Bad(name, "not a splat file this reads (Inria or compressed PLY, .splat, .spz)");
}

absl::StatusOr<int64_t> SplatCount(absl::string_view head, int64_t file_size,
                                   absl::string_view name) {
  ASSIGN_OR_RETURN(SplatFormat format, DetectSplatFormat(head, name));
  switch (format) {
    case SplatFormat::kInriaPly:
    case SplatFormat::kCompressedPly: {
      ASSIGN_OR_RETURN(PlyHeader header, ParsePlyHeader(head, name));
      for (const PlyElement& e : header.elements)
        if (e.name == "vertex") return e.count;
      return Bad(name, "PLY without a vertex element");
    }
    case SplatFormat::kSplat:
      return file_size / static_cast<int64_t>(kSplatRecord);
    case SplatFormat::kSpz: {
      if (IsNgsp(head) && head.size() >= 12) return int64_t{Load<uint32_t>(head.data() + 8)};
      ASSIGN_OR_RETURN(std::string h, Gunzip(head, 16, name));
      if (h.size() < 16) return Bad(name, ".spz: no header");
      return int64_t{Load<uint32_t>(h.data() + 8)};
    }
  }
  return Bad(name, "unknown format");
}

absl::StatusOr<GaussianCloud> ParseSplatFile(absl::string_view data, absl::string_view name) {
  ASSIGN_OR_RETURN(SplatFormat format, DetectSplatFormat(data.substr(0, 1 << 20), name));
  switch (format) {
    case SplatFormat::kInriaPly:
      return ParseGaussianPly(data, name);
    case SplatFormat::kCompressedPly: {
      ASSIGN_OR_RETURN(PlyHeader header, ParsePlyHeader(data, name));
      return splat_decoding::ParseCompressedPly(data, header, name);
    }
    case SplatFormat::kSplat:
      return ParseDotSplat(data, name);
    case SplatFormat::kSpz:
      return splat_decoding::ParseSpz(data, name);
  }
  return Bad(name, "unknown format");
}

absl::StatusOr<GaussianCloud> ReadSplatFile(const std::string& path,
                                            const GaussianPlyOptions& options) {
  ASSIGN_OR_RETURN(std::string data, ReadFileBounded(path, options.max_file_bytes));
  return ParseSplatFile(data, path);
}

std::string EncodeSplat(const GaussianCloud& cloud) {
  std::string out(cloud.size() * kSplatRecord, '\0');
  auto byte = [](double v) { return static_cast<uint8_t>(std::clamp(std::round(v), 0.0, 255.0)); };
  for (size_t i = 0; i < cloud.size(); ++i) {
    char* r = out.data() + kSplatRecord * i;
    for (int a = 0; a < 3; ++a) {
      std::memcpy(r + 4 * a, &cloud.positions[3 * i + a], 4);
      const float s = std::exp(a < cloud.num_scales ? cloud.log_scales[cloud.num_scales * i + a]
                                                    : -13.8f);  // 2DGS: a thin third axis
      std::memcpy(r + 12 + 4 * a, &s, 4);
    }
    auto* b = reinterpret_cast<uint8_t*>(r + 24);
    const float* sh = &cloud.sh[static_cast<size_t>(cloud.sh_stride()) * i];
    for (int a = 0; a < 3; ++a) b[a] = byte((0.5 + kShC0 * sh[a]) * 255);
    b[3] = byte(255 / (1 + std::exp(-static_cast<double>(cloud.opacity_logits[i]))));
    const float* q = &cloud.rotations[4 * i];
    const double len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int a = 0; a < 4; ++a) b[4 + a] = byte(q[a] / len * 128 + 128);
  }
  return out;
}

}  // namespace instascene
