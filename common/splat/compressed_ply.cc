// SuperSplat / PlayCanvas compressed PLY: an elements chunk of per-chunk bounds, a vertex
// element of packed_* words, an optional sh element (splat_formats.h describes the layout).
#include <algorithm>
#include <cmath>
#include <map>
#include <vector>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/splat/splat_decoding.h"

namespace instascene::splat_decoding {
namespace {

constexpr int kChunkSize = 256;  // splats per compressed-PLY chunk

struct ElementSpan {
  const PlyElement* element = nullptr;
  size_t offset = 0;  // of its first row
  size_t row = 0;     // bytes per row
};

using Spans = std::map<std::string, ElementSpan>;

// Each element's byte span (fixed-size rows only). InvalidArgument names a list property or a
// truncated element.
absl::StatusOr<Spans> ElementSpans(absl::string_view data, const PlyHeader& header,
                                   absl::string_view name) {
  Spans spans;
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
  return spans;
}

// The byte offset of property `prop` within a row of `s`, which must have type `type`.
absl::StatusOr<size_t> Column(const ElementSpan& s, absl::string_view prop, ScalarType type,
                              absl::string_view name) {
  size_t at = 0;
  for (const PlyProperty& p : s.element->properties) {
    if (p.name == prop) {
      if (p.type != type)
        return Bad(name, absl::StrCat("compressed PLY: ", s.element->name, ".", prop, " has type ",
                                      ScalarTypeName(p.type)));
      return at;
    }
    at += static_cast<size_t>(ScalarTypeSize(p.type));
  }
  return Bad(name, absl::StrCat("compressed PLY: ", s.element->name, " has no ", prop));
}

// Where every value lies: chunk bounds (positions, scales, optional colours), the packed vertex
// words and the optional quantised higher SH bands.
struct Layout {
  ElementSpan chunk, vertex;
  const ElementSpan* sh = nullptr;
  size_t chunk_at[12], color_at[6], packed_at[4];
  bool chunk_colors = false;
  int sh_degree = 0;
  std::vector<size_t> sh_at;
};

absl::Status ResolveChunkColumns(absl::string_view name, Layout* l) {
  static const char* kChunkProps[] = {"min_x",       "min_y",       "min_z",       "max_x",
                                      "max_y",       "max_z",       "min_scale_x", "min_scale_y",
                                      "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z"};
  static const char* kColorProps[] = {"min_r", "min_g", "min_b", "max_r", "max_g", "max_b"};
  for (int k = 0; k < 12; ++k) {
    ASSIGN_OR_RETURN(l->chunk_at[k], Column(l->chunk, kChunkProps[k], ScalarType::kFloat32, name));
  }
  for (const PlyProperty& p : l->chunk.element->properties) l->chunk_colors |= p.name == "min_r";
  for (int k = 0; l->chunk_colors && k < 6; ++k) {
    ASSIGN_OR_RETURN(l->color_at[k], Column(l->chunk, kColorProps[k], ScalarType::kFloat32, name));
  }
  return absl::OkStatus();
}

absl::StatusOr<Layout> ResolveLayout(const Spans& spans, absl::string_view name) {
  if (!spans.count("chunk") || !spans.count("vertex"))
    return Bad(name, "compressed PLY: needs elements chunk and vertex");
  Layout l;
  l.chunk = spans.at("chunk");
  l.vertex = spans.at("vertex");
  const int64_t n = l.vertex.element->count;
  if (l.chunk.element->count != (n + kChunkSize - 1) / kChunkSize)
    return Bad(name, absl::StrCat("compressed PLY: ", l.chunk.element->count, " chunks for ", n,
                                  " splats (expected one per ", kChunkSize, ")"));
  RETURN_IF_ERROR(ResolveChunkColumns(name, &l));
  static const char* kPacked[] = {"packed_position", "packed_rotation", "packed_scale",
                                  "packed_color"};
  for (int k = 0; k < 4; ++k) {
    ASSIGN_OR_RETURN(l.packed_at[k], Column(l.vertex, kPacked[k], ScalarType::kUint32, name));
  }
  if (!spans.count("sh")) return l;
  l.sh = &spans.at("sh");
  const size_t rest = l.sh->element->properties.size();
  l.sh_degree = rest == 9 ? 1 : rest == 24 ? 2 : rest == 45 ? 3 : -1;
  if (l.sh_degree < 0 || l.sh->element->count != n)
    return Bad(name, "compressed PLY: element sh needs 9, 24 or 45 f_rest_* per splat");
  for (size_t k = 0; k < rest; ++k) {
    ASSIGN_OR_RETURN(size_t at,
                     Column(*l.sh, absl::StrCat("f_rest_", k), ScalarType::kUint8, name));
    l.sh_at.push_back(at);
  }
  return l;
}

double Unorm(uint32_t v, int bits) {
  return static_cast<double>(v & ((1u << bits) - 1)) / ((1u << bits) - 1);
}
double Lerp(double a, double b, double t) { return a * (1 - t) + b * t; }

// Splat i: position and log-scale within its chunk's bounds, the largest-of-four rotation,
// colour and opacity, the higher SH bands.
void DecodeSplat(absl::string_view data, const Layout& l, int64_t i, GaussianCloud* cloud) {
  const char* c = data.data() + l.chunk.offset + l.chunk.row * static_cast<size_t>(i / kChunkSize);
  const char* v = data.data() + l.vertex.offset + l.vertex.row * static_cast<size_t>(i);
  auto chunk_value = [&](int k) { return static_cast<double>(Load<float>(c + l.chunk_at[k])); };
  const uint32_t pos = Load<uint32_t>(v + l.packed_at[0]);
  const uint32_t rot = Load<uint32_t>(v + l.packed_at[1]);
  const uint32_t scl = Load<uint32_t>(v + l.packed_at[2]);
  const uint32_t col = Load<uint32_t>(v + l.packed_at[3]);
  const double p[3] = {Unorm(pos >> 21, 11), Unorm(pos >> 11, 10), Unorm(pos, 11)};
  const double s[3] = {Unorm(scl >> 21, 11), Unorm(scl >> 11, 10), Unorm(scl, 11)};
  for (int a = 0; a < 3; ++a) {
    cloud->positions[3 * i + a] =
        static_cast<float>(Lerp(chunk_value(a), chunk_value(3 + a), p[a]));
    cloud->log_scales[3 * i + a] =
        static_cast<float>(Lerp(chunk_value(6 + a), chunk_value(9 + a), s[a]));
  }
  // Largest of four: the top two bits name the component left out, the others are 10 bits each.
  const double norm = 1.0 / (std::sqrt(2.0) * 0.5);
  const double r[3] = {(Unorm(rot >> 20, 10) - 0.5) * norm, (Unorm(rot >> 10, 10) - 0.5) * norm,
                       (Unorm(rot, 10) - 0.5) * norm};
  const double m = std::sqrt(std::max(0.0, 1.0 - (r[0] * r[0] + r[1] * r[1] + r[2] * r[2])));
  const int largest = static_cast<int>(rot >> 30);
  for (int a = 0, k = 0; a < 4; ++a)
    cloud->rotations[4 * i + a] = static_cast<float>(a == largest ? m : r[k++]);
  const double rgba[4] = {Unorm(col >> 24, 8), Unorm(col >> 16, 8), Unorm(col >> 8, 8),
                          Unorm(col, 8)};
  float* out_sh = &cloud->sh[static_cast<size_t>(cloud->sh_stride()) * i];
  for (int a = 0; a < 3; ++a) {
    const double colour = l.chunk_colors ? Lerp(Load<float>(c + l.color_at[a]),
                                                Load<float>(c + l.color_at[3 + a]), rgba[a])
                                         : rgba[a];
    out_sh[a] = static_cast<float>((colour - 0.5) / kShC0);
  }
  cloud->opacity_logits[i] = AlphaLogit(rgba[3]);
  if (l.sh == nullptr) return;
  const int coeffs = NumShCoeffs(l.sh_degree);
  const char* row = data.data() + l.sh->offset + l.sh->row * static_cast<size_t>(i);
  for (int ch = 0; ch < 3; ++ch) {
    for (int k = 1; k < coeffs; ++k) {
      const uint8_t q = static_cast<uint8_t>(row[l.sh_at[ch * (coeffs - 1) + k - 1]]);
      const double t = q == 0 ? 0.0 : q == 255 ? 1.0 : (q + 0.5) / 256.0;
      out_sh[3 * k + ch] = static_cast<float>((t - 0.5) * 8);
    }
  }
}

}  // namespace

absl::StatusOr<GaussianCloud> ParseCompressedPly(absl::string_view data, const PlyHeader& header,
                                                 absl::string_view name) {
  if (header.format != PlyFormat::kBinaryLittleEndian)
    return Bad(name, "compressed PLY: only binary little-endian is defined");
  ASSIGN_OR_RETURN(const Spans spans, ElementSpans(data, header, name));
  ASSIGN_OR_RETURN(const Layout layout, ResolveLayout(spans, name));
  const int64_t n = layout.vertex.element->count;
  GaussianCloud cloud;
  cloud.num_scales = 3;
  cloud.sh_degree = layout.sh_degree;
  cloud.Resize(static_cast<size_t>(n));
  for (int64_t i = 0; i < n; ++i) DecodeSplat(data, layout, i, &cloud);
  if (absl::Status s = cloud.Validate(); !s.ok()) return Bad(name, s.message());
  return cloud;
}

}  // namespace instascene::splat_decoding
