// common/raster/render_types.h: options and outputs of the CPU Gaussian rasterizer.
//
// Image buffers are row-major, pixel id = row * width + col, channels interleaved (HxWxC).
// Value types; a RenderResult is owned by the caller and safe to read from many threads.
#pragma once

#include <cstdint>
#include <vector>

#include "absl/status/status.h"

namespace instascene {

struct RasterWorkspace;  // rasterizer.h

enum class SplatModel {
  kAuto,      // kSurfel2d for 2-scale clouds, kEllipsoid3d for 3-scale clouds
  kSurfel2d,  // 2DGS ray-splat intersection (ALGORITHM.md 2); needs a 2-scale cloud (see ToSurfels)
  kEllipsoid3d,  // Inria 3DGS EWA splatting with 0.3 px dilation; needs a 3-scale cloud
};

// Contributor tracing: which Gaussians make each pixel, front to back.
struct TraceOptions {
  bool enabled = false;
  // Pixel ids to trace, strictly increasing; empty = every pixel.
  std::vector<uint32_t> pixels;
  // Record only contributions with weight w = alpha * T > min_weight (the tracker rule uses 0.1).
  float min_weight = 0.0f;
  // Also record the transmittance before each contribution (ContributorTrace::transmittance).
  bool transmittance = false;
};

struct RenderOptions {
  SplatModel model = SplatModel::kAuto;
  bool color = true;    // RGB from SH (+ background)
  bool depth = false;   // expected depth and median depth
  bool normal = false;  // accumulated normal, world frame (not normalised, as 2DGS)
  float background[3] = {0.0f, 0.0f, 0.0f};  // RGB added with the final transmittance
  int max_sh_degree = 3;                     // evaluate SH up to min(this, cloud degree)
  float scale_modifier = 1.0f;               // multiplies every scale
  float near_plane = 0.2f;                   // cull / per-pixel near distance, world units
  // Per-Gaussian feature vectors, row-major N x feature_dim (not owned; must outlive Render).
  const float* features = nullptr;
  int feature_dim = 0;
  TraceOptions trace;
  int num_threads = 0;                   // 0 = all cores; results never depend on it
  RasterWorkspace* workspace = nullptr;  // optional reusable scratch (not owned)

  absl::Status Validate() const;
};

// One entry of a pixel's contributor list. 8 bytes: a full trace is tens of millions of entries
// per frame and memory-bound, so the transmittance lives in an optional parallel array.
struct Contribution {
  uint32_t gaussian = 0;  // index into the GaussianCloud
  float weight = 0.0f;    // w = alpha * T, this Gaussian's blending weight at the pixel
};

// Compressed per-pixel lists (CSR): entries[offsets[i] .. offsets[i+1]) belong to pixels[i].
struct ContributorTrace {
  std::vector<uint32_t> pixels;   // traced pixel ids, increasing
  std::vector<uint64_t> offsets;  // pixels.size() + 1
  std::vector<Contribution> entries;
  // T before each entry's Gaussian, parallel to `entries`; filled only when
  // TraceOptions::transmittance is set (empty otherwise).
  std::vector<float> transmittance;

  size_t num_pixels() const { return pixels.size(); }
};

struct RasterStats {
  uint64_t visible_gaussians = 0;    // Gaussians projected onto at least one tile
  uint64_t gaussian_tile_pairs = 0;  // entries of all per-tile lists
  uint64_t evaluated_fragments = 0;  // (pixel, Gaussian) pairs whose alpha was computed
  uint64_t blended_fragments = 0;    // (pixel, Gaussian) pairs actually composited
  double preprocess_ms = 0.0, binning_ms = 0.0, blend_ms = 0.0, trace_assembly_ms = 0.0,
         total_ms = 0.0;
};

struct RenderResult {
  int width = 0;
  int height = 0;
  std::vector<float> color;         // HxWx3 when options.color
  std::vector<float> alpha;         // HxW, 1 - final transmittance (always)
  std::vector<float> depth;         // HxW expected depth (sum w d / alpha; 0 where alpha = 0)
  std::vector<float> median_depth;  // HxW depth where accumulated opacity crosses 0.5
  std::vector<float> normal;        // HxWx3 world frame, when options.normal
  std::vector<float> features;      // HxWxD when features are given
  std::vector<uint32_t> num_contributors;  // HxW Gaussians blended into each pixel
  std::vector<uint8_t> visible;  // per Gaussian: 1 if it touched a tile (2DGS "radii > 0")
  ContributorTrace trace;        // when options.trace.enabled
  RasterStats stats;
};

}  // namespace instascene
