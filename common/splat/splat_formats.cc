#include "common/splat/splat_formats.h"

#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/splat/ply.h"

namespace instascene {
namespace {

constexpr double kShC0 = 0.28209479177387814;
constexpr uint32_t kSpzMagic = 0x5053474e;  // "NGSP" little-endian
constexpr int kChunkSize = 256;             // splats per compressed-PLY chunk
constexpr size_t kSplatRecord = 32;         // bytes per .splat record
constexpr float kSpzColorScale = 0.15f;

absl::Status Bad(absl::string_view name, absl::string_view why) {
  return absl::InvalidArgumentError(absl::StrCat(name, ": ", why));
}

template <typename T>
T Load(const char* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

// An alpha in [0, 1] as a logit (0 and 1 as the finite stand-ins of OpacityLogit).
float AlphaLogit(double alpha) {
  if (!(alpha > 0)) return -kOpaqueLogit;
  if (alpha >= 1) return kOpaqueLogit;
  return static_cast<float>(std::log(alpha / (1 - alpha)));
}

bool IsPly(absl::string_view head) {
  return absl::StartsWith(head, "ply\n") || absl::StartsWith(head, "ply\r\n");
}
bool IsGzip(absl::string_view head) {
  return head.size() >= 2 && static_cast<uint8_t>(head[0]) == 0x1f &&
         static_cast<uint8_t>(head[1]) == 0x8b;
}
bool IsNgsp(absl::string_view head) {
  return head.size() >= 4 && Load<uint32_t>(head.data()) == kSpzMagic;
}

// ---- SuperSplat compressed PLY ----

struct ElementSpan {
  const PlyElement* element = nullptr;
  size_t offset = 0;  // of its first row
  size_t row = 0;     // bytes per row
};

absl::StatusOr<GaussianCloud> ParseCompressedPly(absl::string_view data, const PlyHeader& header,
                                                 absl::string_view name) {
  if (header.format != PlyFormat::kBinaryLittleEndian)
    return Bad(name, "compressed PLY: only binary little-endian is defined");
  std::map<std::string, ElementSpan> spans;
  size_t offset = header.data_offset;
  for (const PlyElement& e : header.elements) {
    ElementSpan span{&e, offset, 0};
    for (const PlyProperty& p : e.properties) {
      if (p.is_list) return Bad(name, absl::StrCat("compressed PLY: list property in ", e.name));
      span.row += static_cast<size_t>(ScalarTypeSize(p.type));
    }
    const size_t bytes = span.row * static_cast<size_t>(e.count);
    if (e.count < 0 || (span.row > 0 && bytes / span.row != static_cast<size_t>(e.count)) ||
        offset + bytes > data.size() || offset + bytes < offset)
      return Bad(name, absl::StrCat("compressed PLY: element ", e.name, " is truncated"));
    offset += bytes;
    spans[e.name] = span;
  }
  auto column = [&](const ElementSpan& s, absl::string_view prop,
                    ScalarType type) -> absl::StatusOr<size_t> {
    size_t at = 0;
    for (const PlyProperty& p : s.element->properties) {
      if (p.name == prop) {
        if (p.type != type)
          return Bad(name, absl::StrCat("compressed PLY: ", s.element->name, ".", prop,
                                        " has type ", ScalarTypeName(p.type)));
        return at;
      }
      at += static_cast<size_t>(ScalarTypeSize(p.type));
    }
    return Bad(name, absl::StrCat("compressed PLY: ", s.element->name, " has no ", prop));
  };
  if (!spans.count("chunk") || !spans.count("vertex"))
    return Bad(name, "compressed PLY: needs elements chunk and vertex");
  const ElementSpan& chunk = spans["chunk"];
  const ElementSpan& vertex = spans["vertex"];
  const int64_t n = vertex.element->count;
  if (chunk.element->count != (n + kChunkSize - 1) / kChunkSize)
    return Bad(name, absl::StrCat("compressed PLY: ", chunk.element->count, " chunks for ", n,
                                  " splats (expected one per ", kChunkSize, ")"));
  static const char* kChunkProps[] = {"min_x",       "min_y",       "min_z",       "max_x",
                                      "max_y",       "max_z",       "min_scale_x", "min_scale_y",
                                      "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z"};
  static const char* kColorProps[] = {"min_r", "min_g", "min_b", "max_r", "max_g", "max_b"};
  size_t chunk_at[12], color_at[6];
  for (int k = 0; k < 12; ++k) {
    ASSIGN_OR_RETURN(chunk_at[k], column(chunk, kChunkProps[k], ScalarType::kFloat32));
  }
  bool chunk_colors = false;
  for (const PlyProperty& p : chunk.element->properties) chunk_colors |= p.name == "min_r";
  for (int k = 0; chunk_colors && k < 6; ++k) {
    ASSIGN_OR_RETURN(color_at[k], column(chunk, kColorProps[k], ScalarType::kFloat32));
  }
  static const char* kPacked[] = {"packed_position", "packed_rotation", "packed_scale",
                                  "packed_color"};
  size_t packed_at[4];
  for (int k = 0; k < 4; ++k) {
    ASSIGN_OR_RETURN(packed_at[k], column(vertex, kPacked[k], ScalarType::kUint32));
  }
  int sh_degree = 0;
  std::vector<size_t> sh_at;
  const ElementSpan* sh = nullptr;
  if (spans.count("sh")) {
    sh = &spans["sh"];
    const size_t rest = sh->element->properties.size();
    sh_degree = rest == 9 ? 1 : rest == 24 ? 2 : rest == 45 ? 3 : -1;
    if (sh_degree < 0 || sh->element->count != n)
      return Bad(name, "compressed PLY: element sh needs 9, 24 or 45 f_rest_* per splat");
    for (size_t k = 0; k < rest; ++k) {
      ASSIGN_OR_RETURN(size_t at, column(*sh, absl::StrCat("f_rest_", k), ScalarType::kUint8));
      sh_at.push_back(at);
    }
  }
  GaussianCloud cloud;
  cloud.num_scales = 3;
  cloud.sh_degree = sh_degree;
  cloud.Resize(static_cast<size_t>(n));
  auto unorm = [](uint32_t v, int bits) {
    return static_cast<double>(v & ((1u << bits) - 1)) / ((1u << bits) - 1);
  };
  auto lerp = [](double a, double b, double t) { return a * (1 - t) + b * t; };
  const double norm = 1.0 / (std::sqrt(2.0) * 0.5);
  const int coeffs = NumShCoeffs(sh_degree);
  for (int64_t i = 0; i < n; ++i) {
    const char* c = data.data() + chunk.offset + chunk.row * static_cast<size_t>(i / kChunkSize);
    const char* v = data.data() + vertex.offset + vertex.row * static_cast<size_t>(i);
    auto chunk_value = [&](int k) { return static_cast<double>(Load<float>(c + chunk_at[k])); };
    const uint32_t pos = Load<uint32_t>(v + packed_at[0]);
    const uint32_t rot = Load<uint32_t>(v + packed_at[1]);
    const uint32_t scl = Load<uint32_t>(v + packed_at[2]);
    const uint32_t col = Load<uint32_t>(v + packed_at[3]);
    const double p[3] = {unorm(pos >> 21, 11), unorm(pos >> 11, 10), unorm(pos, 11)};
    const double s[3] = {unorm(scl >> 21, 11), unorm(scl >> 11, 10), unorm(scl, 11)};
    for (int a = 0; a < 3; ++a) {
      cloud.positions[3 * i + a] =
          static_cast<float>(lerp(chunk_value(a), chunk_value(3 + a), p[a]));
      cloud.log_scales[3 * i + a] =
          static_cast<float>(lerp(chunk_value(6 + a), chunk_value(9 + a), s[a]));
    }
    // Largest of four: the top two bits name the component left out, the others are 10 bits each.
    const double r[3] = {(unorm(rot >> 20, 10) - 0.5) * norm, (unorm(rot >> 10, 10) - 0.5) * norm,
                         (unorm(rot, 10) - 0.5) * norm};
    const double m = std::sqrt(std::max(0.0, 1.0 - (r[0] * r[0] + r[1] * r[1] + r[2] * r[2])));
    const int largest = static_cast<int>(rot >> 30);
    for (int a = 0, k = 0; a < 4; ++a)
      cloud.rotations[4 * i + a] = static_cast<float>(a == largest ? m : r[k++]);
    const double rgba[4] = {unorm(col >> 24, 8), unorm(col >> 16, 8), unorm(col >> 8, 8),
                            unorm(col, 8)};
    float* out_sh = &cloud.sh[static_cast<size_t>(cloud.sh_stride()) * i];
    for (int a = 0; a < 3; ++a) {
      const double colour = chunk_colors ? lerp(Load<float>(c + color_at[a]),
                                                Load<float>(c + color_at[3 + a]), rgba[a])
                                         : rgba[a];
      out_sh[a] = static_cast<float>((colour - 0.5) / kShC0);
    }
    cloud.opacity_logits[i] = AlphaLogit(rgba[3]);
    if (sh != nullptr) {
      const char* row = data.data() + sh->offset + sh->row * static_cast<size_t>(i);
      for (int ch = 0; ch < 3; ++ch) {
        for (int k = 1; k < coeffs; ++k) {
          const uint8_t q = static_cast<uint8_t>(row[sh_at[ch * (coeffs - 1) + k - 1]]);
          const double t = q == 0 ? 0.0 : q == 255 ? 1.0 : (q + 0.5) / 256.0;
          out_sh[3 * k + ch] = static_cast<float>((t - 0.5) * 8);
        }
      }
    }
  }
  if (absl::Status s = cloud.Validate(); !s.ok()) return Bad(name, s.message());
  return cloud;
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

// ---- .spz ----

struct SpzHeader {
  uint32_t version = 0, points = 0;
  int sh_degree = 0, fractional_bits = 0, flags = 0, streams = 0;
  uint32_t toc = 0;
};

int SpzShDim(int degree) { return degree == 0 ? 0 : degree == 1 ? 3 : degree == 2 ? 8 : 15; }

absl::Status CheckSpzHeader(const SpzHeader& h, absl::string_view name) {
  if (h.version < 2 || h.version > 4)
    return Bad(name, absl::StrCat(".spz: version ", h.version, " (versions 2 to 4 are read)"));
  if (h.sh_degree > 3)
    return Bad(name, absl::StrCat(".spz: SH degree ", h.sh_degree, " (at most 3 is supported)"));
  if (h.flags & 0x2)
    return Bad(name, ".spz: the file carries extensions (e.g. a coordinate system), not read here");
  return absl::OkStatus();
}

// Inflates a gzip stream, at most `limit` bytes of output.
absl::StatusOr<std::string> Gunzip(absl::string_view data, size_t limit, absl::string_view name) {
  z_stream z{};
  if (inflateInit2(&z, 16 + MAX_WBITS) != Z_OK) return absl::InternalError("zlib init");
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  z.avail_in = static_cast<uInt>(std::min<size_t>(data.size(), UINT32_MAX));
  std::string out;
  char buffer[1 << 16];
  int rc = Z_OK;
  while (rc == Z_OK && out.size() < limit) {
    z.next_out = reinterpret_cast<Bytef*>(buffer);
    z.avail_out = sizeof(buffer);
    rc = inflate(&z, Z_NO_FLUSH);
    out.append(buffer, sizeof(buffer) - z.avail_out);
  }
  inflateEnd(&z);
  if (rc != Z_STREAM_END && out.size() < limit)
    return Bad(name, absl::StrCat(".spz: the gzip stream is corrupt or truncated (zlib ", rc, ")"));
  if (out.size() > limit) out.resize(limit);
  return out;
}

absl::StatusOr<GaussianCloud> UnpackSpz(const SpzHeader& h, const std::string& positions,
                                        const std::string& alphas, const std::string& colors,
                                        const std::string& scales, const std::string& rotations,
                                        const std::string& sh, absl::string_view name) {
  const size_t n = h.points;
  const int dim = SpzShDim(h.sh_degree);
  const bool smallest_three = h.version >= 3;
  GaussianCloud cloud;
  cloud.num_scales = 3;
  cloud.sh_degree = h.sh_degree;
  cloud.Resize(n);
  const double unit = 1.0 / static_cast<double>(1u << std::min(h.fractional_bits, 30));
  // Right-up-back (spz) to right-down-front (PLY): y and z negated, the quaternion's y and z, and
  // the SH coefficients odd in y or z (the spz library's flip table for this conversion).
  static const float kShFlip[15] = {-1, -1, 1, -1, 1, 1, -1, 1, -1, 1, -1, -1, 1, -1, 1};
  const float axis[3] = {1, -1, -1};
  for (size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      const auto* p = reinterpret_cast<const uint8_t*>(&positions[9 * i + 3 * a]);
      int32_t fixed = p[0] | (p[1] << 8) | (p[2] << 16);
      if (fixed & 0x800000) fixed |= static_cast<int32_t>(0xff000000u);
      cloud.positions[3 * i + a] = static_cast<float>(fixed * unit) * axis[a];
      cloud.log_scales[3 * i + a] = static_cast<uint8_t>(scales[3 * i + a]) / 16.0f - 10.0f;
      cloud.sh[static_cast<size_t>(cloud.sh_stride()) * i + a] =
          (static_cast<uint8_t>(colors[3 * i + a]) / 255.0f - 0.5f) / kSpzColorScale;
    }
    cloud.opacity_logits[i] = AlphaLogit(static_cast<uint8_t>(alphas[i]) / 255.0);
    float q[4];  // x, y, z, w
    if (smallest_three) {
      const auto* r = reinterpret_cast<const uint8_t*>(&rotations[4 * i]);
      uint32_t comp = r[0] | (r[1] << 8) | (r[2] << 16) | (static_cast<uint32_t>(r[3]) << 24);
      const int largest = static_cast<int>(comp >> 30);
      float sum = 0;
      for (int k = 3; k >= 0; --k) {
        if (k == largest) continue;
        const uint32_t mag = comp & 511u;
        const bool negative = (comp >> 9) & 1u;
        comp >>= 10;
        q[k] =
            static_cast<float>(M_SQRT1_2) * static_cast<float>(mag) / 511.0f * (negative ? -1 : 1);
        sum += q[k] * q[k];
      }
      q[largest] = std::sqrt(std::max(0.0f, 1 - sum));
    } else {
      const auto* r = reinterpret_cast<const uint8_t*>(&rotations[3 * i]);
      float sum = 0;
      for (int k = 0; k < 3; ++k) {
        q[k] = r[k] / 127.5f - 1;
        sum += q[k] * q[k];
      }
      q[3] = std::sqrt(std::max(0.0f, 1 - sum));
    }
    float* rot = &cloud.rotations[4 * i];
    rot[0] = q[3];
    for (int k = 0; k < 3; ++k) rot[1 + k] = q[k] * axis[k];
    float* out = &cloud.sh[static_cast<size_t>(cloud.sh_stride()) * i];
    for (int j = 0; j < dim; ++j)
      for (int c = 0; c < 3; ++c)
        out[3 * (j + 1) + c] =
            (static_cast<uint8_t>(sh[(i * dim + j) * 3 + c]) - 128.0f) / 128.0f * kShFlip[j];
  }
  if (absl::Status s = cloud.Validate(); !s.ok()) return Bad(name, s.message());
  return cloud;
}

// Attribute byte counts in file order: positions, alphas, colours, scales, rotations, SH.
std::vector<size_t> SpzSizes(const SpzHeader& h) {
  const size_t n = h.points;
  return {n * 9,
          n,
          n * 3,
          n * 3,
          n * (h.version >= 3 ? 4 : 3),
          n * static_cast<size_t>(SpzShDim(h.sh_degree)) * 3};
}

absl::StatusOr<GaussianCloud> ParseSpz(absl::string_view data, absl::string_view name) {
  SpzHeader h;
  std::vector<std::string> parts(6);
  if (IsGzip(data)) {
    ASSIGN_OR_RETURN(std::string head, Gunzip(data, 16, name));
    if (head.size() < 16 || Load<uint32_t>(head.data()) != kSpzMagic)
      return Bad(name, ".spz: no NGSP header inside the gzip stream");
    h.version = Load<uint32_t>(head.data() + 4);
    h.points = Load<uint32_t>(head.data() + 8);
    h.sh_degree = static_cast<uint8_t>(head[12]);
    h.fractional_bits = static_cast<uint8_t>(head[13]);
    h.flags = static_cast<uint8_t>(head[14]);
    RETURN_IF_ERROR(CheckSpzHeader(h, name));
    if (h.version == 4) return Bad(name, ".spz: version 4 is never gzip-compressed");
    const std::vector<size_t> sizes = SpzSizes(h);
    size_t total = 16;
    for (size_t s : sizes) total += s;
    // A gzip stream expands at most ~1032x: refuse counts the file cannot hold before inflating.
    if (total / 1032 > data.size())
      return Bad(name,
                 absl::StrCat(".spz: ", h.points, " points cannot fit in ", data.size(), " bytes"));
    ASSIGN_OR_RETURN(std::string all, Gunzip(data, total, name));
    if (all.size() < total) return Bad(name, ".spz: the data is shorter than its header says");
    size_t at = 16;
    for (int k = 0; k < 6; ++k) {
      parts[k] = all.substr(at, sizes[k]);
      at += sizes[k];
    }
  } else if (IsNgsp(data) && data.size() >= 32) {
    h.version = Load<uint32_t>(data.data() + 4);
    h.points = Load<uint32_t>(data.data() + 8);
    h.sh_degree = static_cast<uint8_t>(data[12]);
    h.fractional_bits = static_cast<uint8_t>(data[13]);
    h.flags = static_cast<uint8_t>(data[14]);
    h.streams = static_cast<uint8_t>(data[15]);
    h.toc = Load<uint32_t>(data.data() + 16);
    RETURN_IF_ERROR(CheckSpzHeader(h, name));
    if (h.version != 4) return Bad(name, ".spz: an uncompressed header needs version 4");
    const std::vector<size_t> sizes = SpzSizes(h);
    std::vector<int> present;
    for (int k = 0; k < 6; ++k)
      if (sizes[k] > 0) present.push_back(k);
    if (h.streams != static_cast<int>(present.size()) || h.toc < 32 ||
        static_cast<size_t>(h.toc) + 16 * static_cast<size_t>(h.streams) > data.size())
      return Bad(name, absl::StrCat(".spz: ", h.streams, " streams / table at ", h.toc,
                                    " do not match the header"));
    size_t at = h.toc + 16 * static_cast<size_t>(h.streams);
    for (int s = 0; s < h.streams; ++s) {
      const uint64_t compressed = Load<uint64_t>(data.data() + h.toc + 16 * s);
      const uint64_t raw = Load<uint64_t>(data.data() + h.toc + 16 * s + 8);
      const int k = present[s];
      if (raw != sizes[k] || compressed > data.size() - at)
        return Bad(name, absl::StrCat(".spz: stream ", s, " sizes do not match the header"));
      parts[k].resize(sizes[k]);
      const size_t got =
          ZSTD_decompress(parts[k].data(), parts[k].size(), data.data() + at, compressed);
      if (ZSTD_isError(got) || got != sizes[k])
        return Bad(name, absl::StrCat(".spz: stream ", s, " does not decompress (zstd)"));
      at += compressed;
    }
  } else {
    return Bad(name, ".spz: neither a gzip stream nor an NGSP header");
  }
  return UnpackSpz(h, parts[0], parts[1], parts[2], parts[3], parts[4], parts[5], name);
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
      return ParseCompressedPly(data, header, name);
    }
    case SplatFormat::kSplat:
      return ParseDotSplat(data, name);
    case SplatFormat::kSpz:
      return ParseSpz(data, name);
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
