// Niantic / Adobe .spz: versions 2-3 (one gzip stream) and 4 (zstd attribute streams behind a
// table of contents); splat_formats.h describes the encoding and the frame conversion.
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/splat/splat_decoding.h"

namespace instascene::splat_decoding {
namespace {

constexpr float kSpzColorScale = 0.15f;

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

// Quaternion (x, y, z, w) of splat i: v3+ packs the smallest three components (9 bits and a
// sign each, 2 bits naming the largest), v2 stores x, y, z as bytes.
void SpzRotation(const std::string& rotations, size_t i, bool smallest_three, float q[4]) {
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
      q[k] = static_cast<float>(M_SQRT1_2) * static_cast<float>(mag) / 511.0f * (negative ? -1 : 1);
      sum += q[k] * q[k];
    }
    q[largest] = std::sqrt(std::max(0.0f, 1 - sum));
    return;
  }
  const auto* r = reinterpret_cast<const uint8_t*>(&rotations[3 * i]);
  float sum = 0;
  for (int k = 0; k < 3; ++k) {
    q[k] = r[k] / 127.5f - 1;
    sum += q[k] * q[k];
  }
  q[3] = std::sqrt(std::max(0.0f, 1 - sum));
}

absl::StatusOr<GaussianCloud> UnpackSpz(const SpzHeader& h, const std::string& positions,
                                        const std::string& alphas, const std::string& colors,
                                        const std::string& scales, const std::string& rotations,
                                        const std::string& sh, absl::string_view name) {
  const size_t n = h.points;
  const int dim = SpzShDim(h.sh_degree);
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
    SpzRotation(rotations, i, h.version >= 3, q);
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

}  // namespace

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

// Version 2-3: one gzip stream holding the 16-byte header and the six attribute blocks.
absl::Status ReadGzipSpz(absl::string_view data, absl::string_view name, SpzHeader* h,
                         std::vector<std::string>* parts) {
  ASSIGN_OR_RETURN(std::string head, Gunzip(data, 16, name));
  if (head.size() < 16 || Load<uint32_t>(head.data()) != kSpzMagic)
    return Bad(name, ".spz: no NGSP header inside the gzip stream");
  h->version = Load<uint32_t>(head.data() + 4);
  h->points = Load<uint32_t>(head.data() + 8);
  h->sh_degree = static_cast<uint8_t>(head[12]);
  h->fractional_bits = static_cast<uint8_t>(head[13]);
  h->flags = static_cast<uint8_t>(head[14]);
  RETURN_IF_ERROR(CheckSpzHeader(*h, name));
  if (h->version == 4) return Bad(name, ".spz: version 4 is never gzip-compressed");
  const std::vector<size_t> sizes = SpzSizes(*h);
  size_t total = 16;
  for (size_t s : sizes) total += s;
  // A gzip stream expands at most ~1032x: refuse counts the file cannot hold before inflating.
  if (total / 1032 > data.size())
    return Bad(name,
               absl::StrCat(".spz: ", h->points, " points cannot fit in ", data.size(), " bytes"));
  ASSIGN_OR_RETURN(std::string all, Gunzip(data, total, name));
  if (all.size() < total) return Bad(name, ".spz: the data is shorter than its header says");
  size_t at = 16;
  for (int k = 0; k < 6; ++k) {
    (*parts)[k] = all.substr(at, sizes[k]);
    at += sizes[k];
  }
  return absl::OkStatus();
}

// Version 4: a 32-byte header, a table of zstd streams (compressed, raw sizes) and the streams,
// one per attribute block present.
absl::Status ReadZstdSpz(absl::string_view data, absl::string_view name, SpzHeader* h,
                         std::vector<std::string>* parts) {
  h->version = Load<uint32_t>(data.data() + 4);
  h->points = Load<uint32_t>(data.data() + 8);
  h->sh_degree = static_cast<uint8_t>(data[12]);
  h->fractional_bits = static_cast<uint8_t>(data[13]);
  h->flags = static_cast<uint8_t>(data[14]);
  h->streams = static_cast<uint8_t>(data[15]);
  h->toc = Load<uint32_t>(data.data() + 16);
  RETURN_IF_ERROR(CheckSpzHeader(*h, name));
  if (h->version != 4) return Bad(name, ".spz: an uncompressed header needs version 4");
  const std::vector<size_t> sizes = SpzSizes(*h);
  std::vector<int> present;
  for (int k = 0; k < 6; ++k)
    if (sizes[k] > 0) present.push_back(k);
  if (h->streams != static_cast<int>(present.size()) || h->toc < 32 ||
      static_cast<size_t>(h->toc) + 16 * static_cast<size_t>(h->streams) > data.size())
    return Bad(name, absl::StrCat(".spz: ", h->streams, " streams / table at ", h->toc,
                                  " do not match the header"));
  size_t at = h->toc + 16 * static_cast<size_t>(h->streams);
  for (int s = 0; s < h->streams; ++s) {
    const uint64_t compressed = Load<uint64_t>(data.data() + h->toc + 16 * s);
    const uint64_t raw = Load<uint64_t>(data.data() + h->toc + 16 * s + 8);
    const int k = present[s];
    if (raw != sizes[k] || compressed > data.size() - at)
      return Bad(name, absl::StrCat(".spz: stream ", s, " sizes do not match the header"));
    (*parts)[k].resize(sizes[k]);
    const size_t got =
        ZSTD_decompress((*parts)[k].data(), (*parts)[k].size(), data.data() + at, compressed);
    if (ZSTD_isError(got) || got != sizes[k])
      return Bad(name, absl::StrCat(".spz: stream ", s, " does not decompress (zstd)"));
    at += compressed;
  }
  return absl::OkStatus();
}

absl::StatusOr<GaussianCloud> ParseSpz(absl::string_view data, absl::string_view name) {
  SpzHeader h;
  std::vector<std::string> parts(6);
  if (IsGzip(data)) {
    RETURN_IF_ERROR(ReadGzipSpz(data, name, &h, &parts));
  } else if (IsNgsp(data) && data.size() >= 32) {
    RETURN_IF_ERROR(ReadZstdSpz(data, name, &h, &parts));
  } else {
    return Bad(name, ".spz: neither a gzip stream nor an NGSP header");
  }
  return UnpackSpz(h, parts[0], parts[1], parts[2], parts[3], parts[4], parts[5], name);
}

}  // namespace instascene::splat_decoding
