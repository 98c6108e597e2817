// common/mesh/depth_fusion.h: a watertight-where-observed surface from depth maps by TSDF fusion
// and marching cubes (ALGORITHM.md 7.1: the 2DGS `extract_mesh_bounded` recipe), done by Open3D's
// ScalableTSDFVolume (Debian's libopen3d 0.16: a maintained implementation of exactly this recipe,
// so the project writes no TSDF or marching-cubes code of its own), followed by the 2DGS clean-up
// (keep the largest connected components). Open3D is confined to this file's implementation.
// Stateless, thread-safe.
#pragma once

#include <functional>
#include <vector>

#include <Eigen/Geometry>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/geometry/triangle_mesh.h"

namespace instascene {

struct DepthView {
  PinholeCamera camera;
  std::vector<float> depth;  // HxW camera-z depth; 0 or non-finite = no surface
  std::vector<float> color;  // HxWx3 linear RGB in [0, 1], or empty (grey)
  // Optional (closed fusion with carve_views > 0): HxW, for a pixel whose whole ray is empty
  // (a render of the object alone that shows nothing there) its distance in pixels to the
  // nearest pixel that shows the object; 0 elsewhere. Empty = the view carves nothing.
  std::vector<float> empty_distance_px;
};

struct DepthFusionOptions {
  float voxel = 0.0f;                // voxel edge, scene units (> 0)
  float sdf_trunc = 0.0f;            // truncation distance, scene units; 0 = 5 voxels (2DGS)
  float depth_trunc = 0.0f;          // ignore depth beyond this, scene units (> 0)
  int keep_components = 50;          // keep at most this many largest connected components
  int min_component_triangles = 50;  // and drop smaller ones (2DGS post_process_mesh)
  // When not empty, the fusion is closed over this box: a uniform grid over the cube around it
  // (at most `max_closed_resolution` voxels a side; the voxel grows to fit), where every voxel no
  // view observed counts as outside when the grid's border reaches it through voxels not behind
  // a surface, else as inside, and the border as outside. Marching cubes then yields a closed
  // surface: an open TSDF mesh has holes wherever its surface meets space no view looked into (a
  // object's underside seen through a gap, the far side of a thin part). Surface outside the box
  // is cut off there.
  Eigen::AlignedBox3f closed_bounds;
  int max_closed_resolution = 160;  // 160^3 Open3D voxels: about 230 MB
  int closed_gap_voxels = 4;        // the outside does not flow through holes up to twice this wide
  // Closed fusion only: when not zero, voxels with outside_below.head<3>() . x < outside_below[3]
  // are outside (an object's support plane: a truncation band reaching past it is no surface),
  // the renders' visual hull (seen_empty) included.
  Eigen::Vector4f outside_below = Eigen::Vector4f::Zero();
  // Closed fusion only: the surface is extracted where the fused TSDF's projective distance is
  // `inset` (scene units) inside (the TSDF shifted by inset / sdf_trunc before marching cubes);
  // at most half the truncation band. The surface moves by `inset` where the views met it
  // head-on and less where they met it obliquely (0.013 for 0.03 on a sphere fused from a ring).
  float inset = 0.0f;
  // Closed fusion only: silhouette carving. A voxel that projects onto empty pixels
  // (DepthView::empty_distance_px) of at least this many views is outside by the
  // `carve_views`-th largest of those views' distances (the pixel distance times depth over
  // focal length, as a TSDF value); the fused value is raised to it, never lowered. Depth maps
  // alone leave a lip wherever a footprint reaches past an edge that the views seeing past it
  // do not show as surface (a cap's rim seen from above); the views that see past the edge
  // empty remove it. 0 = no carving.
  int carve_views = 0;
  // Closed fusion with carving only, when set: a voxel no depth map reached (unobserved) that
  // projects onto a shown pixel (empty distance 0) of every carving view, and whose centre
  // `seen_empty` does not report (the capture's real views saw empty space there), is inside:
  // the outside does not flow through it. A gap in a completed shell (a face the completion left
  // open) otherwise lets the outside flood the object's unobserved inside, which then meshes as
  // a hollow shell. Called from several threads.
  std::function<bool(const Eigen::Vector3f&)> seen_empty;
};

// Fuses the views into one mesh with vertex colours (closed when options.closed_bounds is set).
// Fails (InvalidArgument) on bad options or a
// view whose buffers do not match its camera.
absl::StatusOr<TriangleMesh> FuseDepthMaps(const std::vector<DepthView>& views,
                                           const DepthFusionOptions& options);

}  // namespace instascene
