#include "services/generation/stage_params.h"

namespace instascene::generation {

namespace {

using O = CompleteStageOptions;

// The prior and what it reads: the viewpoint ring, the free space, the symmetry's agreement.
void AddPriorParams(pipeline::ParamCodec<O>* c) {
  c->Choice(
       "prior", &O::prior, {"geometric", "none", "diffusion"},
       "Completion prior: geometric (symmetry + support, no weights), none (closed crop) or "
       "diffusion (a Denoiser service: instascene complete --denoiser, or workers started with "
       "--denoiser)")
      .Int("ring_views", &O::ring_views, 4, 64, "Cameras on the viewpoint ring")
      .Real("ring_elevation", &O::ring_elevation, -80.0, 80.0, "Ring elevation, degrees")
      .Int("ring_size", &O::ring_size, 32, 1024, "Ring image size, px")
      .Int("top_training_views", &O::top_training_views, 1, 100,
           "Real views kept for refinement (best unoccluded visibility)")
      .Int("free_space_resolution", &O::free_space_resolution, 16, 256,
           "Free-space grid voxels per axis")
      .Real("min_agreement", &O::min_agreement, 0.5, 1.0,
            "Symmetry hypotheses need this share of decided points to agree")
      .Real("min_plane_agreement", &O::min_plane_agreement, 0.5, 1.0,
            "A mirror plane needs this share as well (symmetric shapes agree 0.95 and more; "
            "an L-block's bar with its arm mirrored where no view looked, 0.86-0.91)");
}

// The completed object's mesh (GENERATION.md step 7).
void AddMeshingParams(pipeline::ParamCodec<O>* c) {
  c->Int("mesh_size", &O::mesh_size, 32, 1024, "Meshing view size, px")
      .Real("mesh_min_alpha", &O::mesh_min_alpha, 0.5, 0.99,
            "Meshing: pixels fused into the TSDF need this much alpha (higher: less silhouette "
            "inflation by the surfels' footprint)")
      .Real("mesh_inset_sigmas", &O::mesh_inset_sigmas, 0.0, 2.0,
            "Meshing: the closed surface is moved this many median surfel sigmas inward (the "
            "surfels' footprints stand about half a sigma past the true surface)")
      .Real("mesh_snap_spacings", &O::mesh_snap_spacings, 0.0, 8.0,
            "Meshing: each vertex of the closed surface moves along its normal onto the "
            "outermost layer of the surfel centres within this many surfel spacings (0 = off)")
      .Int("mesh_carve_views", &O::mesh_carve_views, 0, 64,
           "Meshing: silhouette carving; a voxel this many meshing renders see past (alpha "
           "below 0.9 where it projects, gaps between surfels closed) is outside the closed "
           "surface (0 = off)")
      .Bool("mesh_cull_inner_sides", &O::mesh_cull_inner_sides,
            "Meshing: each render fuses depth only from the surfels whose outer side (the side "
            "the meshing renders see most) faces it, so a view through a hole in a completed "
            "shell does not empty the object's inside")
      .Bool("mesh_enclose_hull", &O::mesh_enclose_hull,
            "Meshing: space no render's depth reached, shown by every render and not seen "
            "empty by the capture, is inside the closed surface (not about an accepted "
            "rotation axis: a cup's cavity stays open)");
}

// The instance's floor, the joint refinement and the diffusion prior's sampler.
void AddRefinementParams(pipeline::ParamCodec<O>* c) {
  c->Int("min_gaussians", &O::min_gaussians, 1, 1000000,
         "Instances with fewer Gaussians fail as degenerate")
      .Int("refine_iterations", &O::refine_iterations, 0, 20000,
           "Joint refinement iterations (one view, one Adam step each); 0 = not run")
      .Int("refine_view_size", &O::refine_view_size, 32, 1024,
           "Joint refinement: real views are cropped to the object and binned to at most this, "
           "px")
      .Real("refine_lambda_normal", &O::refine_lambda_normal, 0.0, 10.0,
            "Joint refinement: weight of 2DGS's depth-normal consistency on the real views "
            "(0 = off)")
      .Real("diffusion_replace_fraction", &O::diffusion_replace_fraction, 0.0, 1.0,
            "Diffusion prior: known pixels replace the sampler's during this share of the "
            "steps, from the noisiest (1 = every step, RePaint; 0 = never)")
      .Choice("diffusion_warp", &O::diffusion_warp, {"latent", "pixel"},
              "Diffusion prior: warp known views on the latent grid, or at the ring's "
              "resolution and then encode (a latent cell is known where most of its pixels are)")
      .Bool("diffusion_unseen_mask", &O::diffusion_unseen_mask,
            "Diffusion prior: generate only where a target pixel looks at space no real view "
            "saw (ALGORITHM.md 7.8) or at the object itself; elsewhere the view is background")
      .Int<uint64_t>("prior_seed", &O::seed, 0, int64_t{1} << 53,
                     "Random seed of the completion prior");
}

}  // namespace

const pipeline::ParamCodec<CompleteStageOptions>& CompleteCodec() {
  static const auto* codec = [] {
    auto* c = new pipeline::ParamCodec<O>("complete");
    AddPriorParams(c);
    AddMeshingParams(c);
    AddRefinementParams(c);
    return c;
  }();
  return *codec;
}

pipeline::StageSpec CompleteSpec() {
  pipeline::StageSpec spec = pipeline::MakeStageSpec(
      "complete", "objects",
      "In-situ completion of one object: viewpoint ring, free space, completion prior, mesh",
      {{"segment", pipeline::InputMode::kEach}}, /*fans_out=*/false, CompleteCodec());
  spec.required_outputs = {"manifest.json"};
  return spec;
}

}  // namespace instascene::generation
