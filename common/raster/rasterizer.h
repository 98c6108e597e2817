// common/raster/rasterizer.h: the CPU Gaussian-splat rasterizer with contributor tracing.
//
// Renders a GaussianCloud from a PinholeCamera exactly as the 2DGS CUDA rasterizer does
// (ALGORITHM.md section 2: 16x16 tiles, per-tile front-to-back order by centre depth, 3-sigma
// cutoff, low-pass filter, alpha clamp 0.99, skip alpha < 1/255, stop at T < 1e-4, median-depth
// rule), or as the Inria 3DGS rasterizer for 3-scale clouds. Tiles run in parallel with TBB; every
// tile is computed by one task from the same inputs, so results are bit-identical for any thread
// count. Thread-safe: Render has no shared mutable state.
#pragma once

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/raster/render_types.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene {

struct ProjectedSplat;
namespace raster_internal {
struct TileTrace;
}

// Scratch buffers Render reuses across calls when RenderOptions::workspace points here (saves the
// page faults of re-allocating ~100 bytes per Gaussian every frame). Not thread-safe: one workspace
// per concurrent Render.
struct RasterWorkspace {
  RasterWorkspace();
  ~RasterWorkspace();
  std::vector<ProjectedSplat> splats;
  std::vector<uint64_t> keys, tile_offsets, chunk_cursors;
  std::vector<raster_internal::TileTrace> tile_traces;
};

// Renders `cloud` seen by `camera`. Fails (InvalidArgument) on an invalid camera or options, a
// feature buffer of the wrong size, or a model that does not match the cloud's scale count.
// The cloud must have passed GaussianCloud::Validate (readers guarantee it).
absl::StatusOr<RenderResult> Render(const GaussianCloud& cloud, const PinholeCamera& camera,
                                    const RenderOptions& options);

// The same, rendering into `result` and reusing its buffers' capacity (no page faults for a
// caller that renders many frames, e.g. a tracker tracing every view).
absl::Status RenderInto(const GaussianCloud& cloud, const PinholeCamera& camera,
                        const RenderOptions& options, RenderResult* result);

// Resolves kAuto against the cloud.
SplatModel ResolveModel(const GaussianCloud& cloud, SplatModel requested);

}  // namespace instascene
