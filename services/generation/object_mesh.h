// services/generation/object_mesh.h: renders an object's surfels alone and turns them into a
// closed, coloured triangle mesh (GENERATION.md step 6: TSDF fusion of depth maps + marching
// cubes, common/mesh/depth_fusion.h). The meshing views cover the whole sphere around the object
// (five elevation rings and both poles), so a completed object yields a closed mesh; the raw crop
// meshed the same way is the "closed crop" baseline. Thread-safe.
#pragma once

#include <functional>
#include <vector>

#include "absl/status/statusor.h"
#include "common/geometry/triangle_mesh.h"
#include "common/splat/gaussian_cloud.h"
#include "services/generation/object_frame.h"
#include "services/generation/prior.h"

namespace instascene::generation {

// The instance rendered alone at `camera` on white (RGB, median depth, alpha, mask alpha > 0.5).
// `scale_modifier` > 1 inflates every surfel (meshing: closes the gaps a sparse shell has, which
// would otherwise let depth maps see its inner side and fuse a hollow mesh).
absl::StatusOr<ViewImages> RenderObjectView(const GaussianCloud& object,
                                            const PinholeCamera& camera, const ObjectFrame& frame,
                                            int num_threads, float scale_modifier = 1.0f);

struct MeshingOptions {
  int size_px = 160;              // meshing view size
  int azimuths = 12;              // per elevation ring
  float voxel_radii = 1.0f / 40;  // TSDF voxel in object radii
  float scale_modifier = 1.0f;    // surfel inflation of the meshing renders
  // Pixels fused into the TSDF need this alpha (>= 0.5, the view mask's threshold). Past an
  // object's silhouette, a surfel's footprint keeps alpha > 0.5 up to ~1.18 sigma beyond its
  // centre, which widens the mesh; a higher threshold trims that lip (0.9: mean largest extent
  // error of exported objects 0.28 -> 0.25 on tiny scenes, seeds 3-5, docs/OBJECTS.md).
  float min_alpha = 0.9f;
  // Surfels are rendered for meshing with their scales clamped to this many times the object's
  // surfel spacing (ObjectFrame::spacing; 0 = no clamp). A surfel that much larger than its
  // neighbours' spacing is a blur, not surface detail: a few such footprints (a cap surfel that
  // took a large source's scale, a stray of the support) become sheets of false surface in the
  // fused mesh. 3: pipeline completion, seeds 21-24, volume IoU 0.715 -> 0.776, Chamfer / diag
  // 0.0224 -> 0.0120 (docs/RESULTS.md, "Meshing: surfel scale clamp"); tighter clamps (1-2
  // spacings) open gaps between the surfels and leave hollow meshes.
  float max_scale_spacings = 3.0f;
  // Close the fused surface (DepthFusionOptions::closed_bounds over the object's surfels): space
  // no meshing view looked into counts as inside unless the outside reaches it.
  bool closed = true;
  // Closed meshing: the outside does not flow through holes up to twice this wide (voxels;
  // DepthFusionOptions::closed_gap_voxels). 8 (0.4 R): a completed shell with a refused patch
  // stays solid (pipeline completion, seeds 21-24, volume IoU 0.835 -> 0.852: a box 0.37 -> 0.88,
  // a torus 0.19 -> 0.41), at the price of openings narrower than that (a cup 0.64 -> 0.57, the
  // bowl 0.77 -> 0.72; docs/RESULTS.md "Meshing: the closing's gap").
  int closed_gap_voxels = 8;
  // The depth each meshing view fuses comes only from the surfels whose outer side faces it
  // (outer: the side the meshing views' blending weight sees each surfel from most). A view
  // through a hole in a completed shell (a refused patch) then fuses nothing there instead of
  // the far walls' inner sides, which would mark the object's inside as empty.
  bool cull_inner_sides = true;
  // Closed meshing with carving, given the capture's seen-empty space (MeshObject's
  // `seen_empty`): voxels no render's depth reached that every render shows, and the real views
  // did not see empty, are inside (DepthFusionOptions::seen_empty). Without it a gap the
  // completion left in the shell (a face seen only edge-on, an asymmetric object's unseen back)
  // lets the closing flood the inside: a hollow shell (irregular blocks 0.36-0.51 volume IoU).
  // The completion does not apply it about an accepted axis of revolution (a cup's cavity would
  // fill); a box's n-fold axis gets it (a face seen only edge-on leaves a gap). Measured in
  // docs/RESULTS.md ("Meshing: the renders' visual hull").
  bool enclose_hull = true;
  // Closed meshing only: the surface is moved this many of the object's median surfel sigma
  // inward (DepthFusionOptions::inset, at most half the truncation band). A surfel's footprint
  // keeps alpha > min_alpha up to about half a sigma past the true silhouette, so the fused
  // surface stands that far outside the object. 0.4: pipeline completion, seeds 21-24, mean
  // largest extent error 0.112 -> 0.076, volume IoU 0.802 -> 0.835 (docs/RESULTS.md "Meshing:
  // the footprint inset").
  float inset_sigmas = 0.4f;
  // Closed meshing only: silhouette carving (DepthFusionOptions::carve_views). Pixels of a
  // meshing render with alpha below `empty_alpha` see nothing of the object, once the object's
  // pixels are closed (morphologically) with a disc of `empty_close_px` at a 160 px render
  // (scaled with size_px) so that gaps between sparse surfels do not count; a voxel that
  // `carve_views` renders see past is outside. 0 = off. Chosen on seeds 21-24, checked on held-out
  // sets (docs/RESULTS.md "Meshing: silhouette carving").
  int carve_views = 2;
  float empty_alpha = 0.9f;
  float empty_close_px = 9.0f;
  // Closed meshing only: each vertex of the fused surface is moved along its normal onto the
  // outermost layer of the surfel centres facing its way within `snap_radius_spacings` surfel
  // spacings (ObjectFrame::spacing; SnapToSurfels, common/mesh/surfel_snap.h), by at most
  // `snap_max_voxels` fusion voxels; surfels within `snap_layer_spacings` of the layer's third
  // outermost form it (fewer strays farther out do not hold the surface out). Then a vertex
  // farther than `snap_reach_spacings` from every surfel centre (a lip past a rim or a top edge)
  // is pulled towards the nearest one. The inset alone moves the surface by one amount
  // everywhere; the snap moves each part by what its own surfels say. 3 / 0.5 / 2 / 0.5:
  // pipeline completion, seeds 21-24, volume IoU 0.883 -> 0.911, extents within 5 % 15 -> 26
  // of 32 (docs/RESULTS.md "Meshing: vertices snapped to the surfels"). 0 radius = off.
  float snap_radius_spacings = 3.0f;
  float snap_layer_spacings = 0.5f;
  float snap_max_voxels = 2.0f;
  float snap_reach_spacings = 0.5f;
  // Closed meshing with a support only: the base's vertices (within a voxel of the support) keep
  // their height but slide across the up direction onto the surfels facing their way, the layer
  // extrapolated down to their height (SurfelSnapOptions::slide_normal); without it they are
  // fixed, and a fused lip past a bottle's foot stayed.
  bool snap_base_across = true;
  // Closed meshing with a support only: before the snap, the lowest voxel's layer of vertices is
  // lowered together onto the support, by at most a voxel (the fused floor stood a fraction of a
  // voxel above the plane it was cut at: bottles 0.74 mm short). Both measured in
  // docs/RESULTS.md "Meshing: the base on its support".
  bool base_on_support = true;
  // Closed meshing with a support only: after the clamps, the base's outer ring (its vertices
  // within a voxel of the support) moves outward onto its side's foot, the side's surfels taken
  // down their slope to the support where that side narrows upwards (ExtendRimToSide,
  // common/mesh/surfel_snap.h; the neighbourhood twice the snap's): a cone's lowest surfels stand
  // a few millimetres above the support, inside the true rim, and the ring stood 1-3 mm inside
  // it (docs/RESULTS.md "Meshing: a cone's rim at its side's foot").
  bool rim_to_side = true;
  // Closed meshing only: no vertex stands higher (along the frame's up) than the object's highest
  // surfel centre; those above it are lowered onto that height. A surfel's footprint reaches past
  // a top face's edge and a rim's, and the fused top stood 2.2 mm (median; cups' rims 4.7 mm)
  // above the true one, which the surfel centres reach to within their spacing (docs/RESULTS.md
  // "Meshing: nothing above the highest surfel").
  bool top_at_highest_surfel = true;
  // Closed meshing only: no vertex stands farther out along any of 64 horizontal directions of
  // the object's frame than the farthest surfel centre: the sides' counterpart of
  // `top_at_highest_surfel` (a footprint's lip past a body's widest point made bottles 1-4 mm
  // wide). Not where the visual hull encloses the object (`enclose_hull` with `seen_empty`
  // given): there the surface closes an unseen side past the surfels, which the clamp would cut
  // (docs/RESULTS.md "Meshing: no side past the outermost surfels"); unless the surfels stand all
  // round it (MeshObject's `surfels_all_round`: a box's n-fold copies).
  bool sides_within_surfels = true;
  // The completion meshes an object an accepted n-fold axis completed (a box) with
  // `surfels_all_round`: the copies stand on every side.
  bool sides_within_order_axis_copies = true;
};

// The meshing cameras: elevations -60, -30, 0, 30, 60 degrees x `azimuths`, plus both poles.
std::vector<PinholeCamera> MeshingCameras(const ObjectFrame& frame, const MeshingOptions& options);

// `seen_empty` (optional): the capture's seen-empty space; with it the closed surface encloses
// what the meshing renders' visual hull holds and no depth map reached, except that space
// (DepthFusionOptions::seen_empty). `surfels_all_round`: the object's surfels stand on every side
// of it (an n-fold axis's copies, a box's), so `sides_within_surfels` applies with `seen_empty`
// too: the hull closes gaps between them, not an unseen side beyond them.
absl::StatusOr<TriangleMesh> MeshObject(const GaussianCloud& object, const ObjectFrame& frame,
                                        const MeshingOptions& options, int num_threads,
                                        std::function<bool(const Eigen::Vector3f&)> seen_empty = {},
                                        bool surfels_all_round = false);

}  // namespace instascene::generation
