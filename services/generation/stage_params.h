// services/generation/stage_params.h: the `complete` stage as every binary can link it: its spec
// and one parameter codec. Light: no ray casting, no meshing library.
#pragma once

#include <cstdint>
#include <string>

#include "services/pipeline/stage.h"

namespace instascene::generation {

// What a complete job takes (a subset of CompletionOptions, the rest are the documented defaults).
struct CompleteStageOptions {
  std::string prior = "geometric";  // geometric | none
  int ring_views = 16;              // viewpoint ring (ALGORITHM.md 7.2)
  double ring_elevation = 30.0;     // degrees
  int ring_size = 256;              // px
  int top_training_views = 10;
  int free_space_resolution = 64;     // voxels per axis
  double min_agreement = 0.85;        // symmetry acceptance
  double min_plane_agreement = 0.93;  // a mirror plane's acceptance (SymmetryOptions)
  int mesh_size = 160;                // meshing view size, px
  double mesh_min_alpha = 0.9;        // meshing: alpha a fused pixel needs
  double mesh_inset_sigmas = 0.4;     // meshing: surface moved inward, in median surfel sigmas
  int mesh_carve_views = 2;           // meshing: renders that must see past a voxel to carve it
  bool mesh_cull_inner_sides = true;  // meshing: depth only from surfels facing each view
  bool mesh_enclose_hull = true;      // meshing: the renders' visual hull is inside
  double mesh_snap_spacings = 3.0;  // meshing: vertices snapped to surfels this many spacings near
  int min_gaussians = 50;           // fewer: a degenerate object (fails permanently)
  // Joint refinement (ALGORITHM.md 7.9); 0 = not run. Off by default: with the geometric prior it
  // measured no gain at the 2DGS learning rates (docs/RESULTS.md "Joint refinement"); the
  // prototype's setting is 2000.
  int refine_iterations = 0;
  int refine_view_size = 256;               // real views cropped and binned to at most this, px
  double refine_lambda_normal = 0.05;       // depth-normal consistency on the real views (2DGS)
  double diffusion_replace_fraction = 1.0;  // diffusion prior: steps that replace known pixels
  std::string diffusion_warp = "latent";    // diffusion prior: latent | pixel
  bool diffusion_unseen_mask = true;        // diffusion prior: the 7.8 generation mask
  uint64_t seed = 1;
};

const pipeline::ParamCodec<CompleteStageOptions>& CompleteCodec();
pipeline::StageSpec CompleteSpec();  // input: each item of segment

}  // namespace instascene::generation
