// common/splat/splat_decoding.h: what the splat format decoders share (splat_formats.cc,
// compressed_ply.cc, spz.cc); internal to common/splat.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "common/splat/gaussian_cloud.h"
#include "common/splat/gaussian_ply.h"
#include "common/splat/ply.h"

namespace instascene::splat_decoding {

inline constexpr double kShC0 = 0.28209479177387814;
inline constexpr uint32_t kSpzMagic = 0x5053474e;  // "NGSP" little-endian

inline absl::Status Bad(absl::string_view name, absl::string_view why) {
  return absl::InvalidArgumentError(absl::StrCat(name, ": ", why));
}

template <typename T>
T Load(const char* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

// An alpha in [0, 1] as a logit (0 and 1 as the finite stand-ins of OpacityLogit).
inline float AlphaLogit(double alpha) {
  if (!(alpha > 0)) return -kOpaqueLogit;
  if (alpha >= 1) return kOpaqueLogit;
  return static_cast<float>(std::log(alpha / (1 - alpha)));
}

inline bool IsGzip(absl::string_view head) {
  return head.size() >= 2 && static_cast<uint8_t>(head[0]) == 0x1f &&
         static_cast<uint8_t>(head[1]) == 0x8b;
}

inline bool IsNgsp(absl::string_view head) {
  return head.size() >= 4 && Load<uint32_t>(head.data()) == kSpzMagic;
}

// SuperSplat / PlayCanvas compressed PLY (compressed_ply.cc).
absl::StatusOr<GaussianCloud> ParseCompressedPly(absl::string_view data, const PlyHeader& header,
                                                 absl::string_view name);

// Niantic / Adobe .spz, versions 2-4 (spz.cc).
absl::StatusOr<GaussianCloud> ParseSpz(absl::string_view data, absl::string_view name);

// Inflates a gzip stream, at most `limit` bytes of output (spz.cc).
absl::StatusOr<std::string> Gunzip(absl::string_view data, size_t limit, absl::string_view name);

}  // namespace instascene::splat_decoding
