// common/splat/splat_formats.h: the splat files users' tools export, read into a GaussianCloud
// (then written as the internal PLY on ingest):
//   - Inria / 2DGS PLY (gaussian_ply.h);
//   - SuperSplat / PlayCanvas compressed PLY (elements chunk + vertex of packed_* words + optional
//     sh; 256 splats per chunk, positions and log-scales 11-10-11 bits between the chunk's bounds,
//     colour and opacity 8 bits each, rotation "largest of four" 2-10-10-10, SH in 8 bits);
//   - antimatter15 .splat (32-byte records: position, linear scales, RGBA bytes, quaternion bytes);
//   - Niantic / Adobe .spz, versions 2-3 (one gzip stream) and 4 (zstd attribute streams behind a
//     table of contents): 24-bit fixed-point positions, 8-bit log-scales, alpha, colour, SH and
//     quaternions, stored in the right-up-back frame and converted here to the PLY's
//     right-down-front one (y and z negated, quaternions and SH coefficients flipped to match).
// Each decoder follows what @playcanvas/splat-transform and the spz library decode, so that a file
// loads here as it loads there (tests/splat_formats_test.sh checks that on files splat-transform
// wrote). Values those tools legitimately write load as what they mean: an alpha of exactly 0 or 1
// (a logit of -inf / +inf) is opacity 0 / 1 (OpacityLogit); NaN stays an error. Inputs are bounded
// (sizes are checked against the bytes present before anything is allocated; decompressed sizes
// must match the header's counts). Stateless, thread-safe.
#pragma once

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "common/splat/gaussian_cloud.h"
#include "common/splat/gaussian_ply.h"

namespace instascene {

enum class SplatFormat { kInriaPly, kCompressedPly, kSplat, kSpz };
absl::string_view SplatFormatName(SplatFormat format);  // "ply", "compressed ply", "splat", "spz"

// By content (PLY header, gzip or NGSP magic), else by name (".splat"). `head`: the file's first
// bytes (a PLY's whole header; 64 KiB is plenty for any other format).
absl::StatusOr<SplatFormat> DetectSplatFormat(absl::string_view head, absl::string_view name);

// The number of Gaussians, from the first bytes of a file (`head`: its first MiB or all of it) and
// its size, without decoding it (for limits checked before a job runs).
absl::StatusOr<int64_t> SplatCount(absl::string_view head, int64_t file_size,
                                   absl::string_view name);

// Any of the formats above; `name` names the file in errors and decides for .splat.
absl::StatusOr<GaussianCloud> ParseSplatFile(absl::string_view data, absl::string_view name);
absl::StatusOr<GaussianCloud> ReadSplatFile(const std::string& path,
                                            const GaussianPlyOptions& options = {});

// A .splat file (positions, linear scales, 8-bit colour and opacity, 8-bit quaternion; SH above
// degree 0 dropped), as antimatter15's converter writes it: for interchange and tests.
std::string EncodeSplat(const GaussianCloud& cloud);

}  // namespace instascene
