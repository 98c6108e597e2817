// services/generation/completion.h: in-situ completion of one decomposed object (paper section
// 3.3; GENERATION.md steps 1-6): split the instance from its occluders, frame it, score the
// viewpoint ring and rank the real views by unoccluded visibility, carve the space real views saw
// empty, render the condition views, run the completion prior, and mesh the result. Everything
// stays in the scene's frame ("in situ"); every Gaussian of the output carries its provenance
// (PLY property `provenance`: 0 observed, 1 completed). The joint refinement (step 5,
// refinement.h) runs on the ring views and, when a view loader is given, on crops of the real
// training views; the manifest reports it (`refinement`).
// Deterministic for a given input and seed; thread-count independent. Thread-safe.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "common/core/cancel.h"
#include "common/geometry/triangle_mesh.h"
#include "common/scene/image_io.h"
#include "common/splat/gaussian_cloud.h"
#include "services/generation/free_space.h"
#include "services/generation/geometric_prior.h"
#include "services/generation/object_frame.h"
#include "services/generation/object_mesh.h"
#include "services/generation/prior.h"
#include "services/generation/refinement.h"
#include "services/generation/viewpoints.h"

namespace instascene::generation {

inline constexpr char kObjectFormat[] = "instascene.object/1";
inline constexpr char kProvenanceChannel[] = "provenance";

// The RGB image of real view `view` (an index into the scene's cameras).
using ViewImageLoader = std::function<absl::StatusOr<Image>(int view)>;

struct CompletionOptions {
  std::string prior = "geometric";  // geometric | none | diffusion
  std::string denoiser;  // the diffusion prior's denoiser: grpc://HOST:PORT or onnx:FILE.json
  DiffusionSettings diffusion;      // the diffusion prior's replacement schedule and warp space
  GeometricPriorOptions geometric;  // the geometric prior's symmetry tests and rules
  RingOptions ring;
  VisibilityOptions visibility;
  FreeSpaceOptions free_space;
  SeenThroughOptions seen_through;  // the exact free-space test of completion candidates
  MeshingOptions meshing;
  int top_training_views = 10;  // real views kept for refinement (ALGORITHM.md 7.3)
  size_t min_gaussians = 50;    // fewer: a degenerate object, failed permanently
  // Joint refinement; off unless iterations > 0 (the stage default, see stage_params.h).
  RefinementOptions refinement{.iterations = 0};
  int refine_view_max_side = 256;  // real views are cropped and binned to at most this, px
  // Real images for the refinement; nullptr: it uses the generated (ring) views only.
  ViewImageLoader load_view;
  uint64_t seed = 1;
  int num_threads = 0;                 // 0 = all cores; never changes results
  const CancelFlag* cancel = nullptr;  // not owned
};

using CompletionProgress = std::function<void(const std::string& phase, int step, int total)>;

struct CompletedObject {
  uint32_t id = 0;
  ObjectFrame frame;
  GaussianCloud raw;  // the observed instance (the raw crop), stray Gaussians removed
  size_t stray_removed = 0;
  GaussianCloud object;        // observed + completed, with the provenance channel
  TriangleMesh mesh;           // closed mesh of `object`
  bool hull_enclosed = false;  // the mesh enclosed the renders' visual hull (enclose_hull)
  std::vector<PinholeCamera> ring;
  std::vector<ViewVisibility> ring_visibility;
  std::vector<int> training_views;  // indices into the scene's views, best first
  PriorOutput prior;
  nlohmann::json refinement;  // the manifest's `refinement`: status, views, losses, time
  nlohmann::json manifest;
};

// `cameras` are the scene's real views, `surfels` the scene's Gaussians as 2DGS surfels, `labels`
// the segmentation (one per Gaussian). FailedPrecondition for an empty or degenerate instance or
// one no real view sees (the message names the instance); InvalidArgument for a bad prior name.
absl::StatusOr<CompletedObject> CompleteObject(const std::vector<PinholeCamera>& cameras,
                                               const GaussianCloud& surfels,
                                               const std::vector<uint32_t>& labels, uint32_t id,
                                               const CompletionOptions& options,
                                               const CompletionProgress& progress = nullptr);

// Writes <dir>/object.ply (full-attribute PLY with provenance), mesh.ply, manifest.json and
// views/{raw,completed}_unknown.png (the raw crop and the completed object from the least-known
// ring view, side by side in views/compare_unknown.png).
absl::Status WriteCompletedObject(const std::string& directory, const CompletedObject& object,
                                  int num_threads);

}  // namespace instascene::generation
