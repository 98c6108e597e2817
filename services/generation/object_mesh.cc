#include "services/generation/object_mesh.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

#include "common/core/status.h"
#include "common/geometry/rigid.h"
#include "common/mesh/depth_fusion.h"
#include "common/mesh/surfel_snap.h"
#include "common/raster/rasterizer.h"
#include "services/generation/viewpoints.h"

namespace instascene::generation {
namespace {

// The ring sits a few radii away: the default 0.2-unit near plane would cull small objects.
float ObjectNearPlane(const PinholeCamera& camera, const ObjectFrame& frame) {
  return std::max(1e-6f, 0.01f * (camera.CenterInWorld().cast<float>() - frame.center).norm());
}

// Surfel centres and unit normals (the rotation's third column) of a 2DGS cloud.
void SurfelGeometry(const GaussianCloud& cloud, std::vector<Eigen::Vector3f>* positions,
                    std::vector<Eigen::Vector3f>* normals) {
  positions->resize(cloud.size());
  normals->resize(cloud.size());
  for (size_t g = 0; g < cloud.size(); ++g) {
    (*positions)[g] = Eigen::Vector3f(&cloud.positions[3 * g]);
    const float* q = &cloud.rotations[4 * g];
    (*normals)[g] = RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]).cast<float>().col(2);
  }
}

// Per surfel, its normal turned to the side from which the views' blending weight sees it most
// (MeshingOptions::cull_inner_sides). A surfel no view sees keeps its normal as it is: whichever
// views it is then culled for, it is hidden behind others in all of them.
absl::StatusOr<std::vector<Eigen::Vector3f>> OutwardNormals(
    const GaussianCloud& object, const std::vector<Eigen::Vector3f>& position,
    std::vector<Eigen::Vector3f> normal, const ObjectFrame& frame,
    const std::vector<PinholeCamera>& cameras, int num_threads) {
  std::vector<double> vote(object.size(), 0.0);
  RenderOptions options;
  options.color = false;
  options.num_threads = num_threads;
  options.trace.enabled = true;
  RasterWorkspace workspace;
  options.workspace = &workspace;
  RenderResult traced;
  for (const PinholeCamera& camera : cameras) {
    const Eigen::Vector3f eye = camera.CenterInWorld().cast<float>();
    options.near_plane = ObjectNearPlane(camera, frame);
    RETURN_IF_ERROR(RenderInto(object, camera, options, &traced));
    for (const Contribution& c : traced.trace.entries) {
      const float side = normal[c.gaussian].dot(eye - position[c.gaussian]);
      vote[c.gaussian] += side >= 0 ? c.weight : -c.weight;
    }
  }
  for (size_t g = 0; g < object.size(); ++g) {
    if (vote[g] < 0) normal[g] = -normal[g];
  }
  return normal;
}

// Every vertex is moved inside the polygon of the surfel centres' extremes along 64 horizontal
// directions of the object's frame (each half-plane in turn, three passes); heights are kept
// (MeshingOptions::sides_within_surfels).
void ClampToSurfelPolygon(const std::vector<Eigen::Vector3f>& points, const ObjectFrame& frame,
                          TriangleMesh* mesh) {
  constexpr int kDirections = 64;
  const Eigen::Matrix3f basis = frame.Basis();
  std::vector<Eigen::Vector3f> directions;
  std::vector<float> reach;
  for (int a = 0; a < kDirections; ++a) {
    const float azimuth = 2 * 3.14159265f * a / kDirections;
    directions.push_back(basis.col(0) * std::cos(azimuth) + basis.col(1) * std::sin(azimuth));
    float most = -std::numeric_limits<float>::infinity();
    for (const Eigen::Vector3f& p : points) most = std::max(most, directions.back().dot(p));
    reach.push_back(most);
  }
  for (Eigen::Vector3f& v : mesh->vertices) {
    for (int pass = 0; pass < 3; ++pass) {
      for (int d = 0; d < kDirections; ++d) {
        const float excess = directions[d].dot(v) - reach[d];
        if (excess > 0) v -= excess * directions[d];
      }
    }
  }
}

}  // namespace

absl::StatusOr<ViewImages> RenderObjectView(const GaussianCloud& object,
                                            const PinholeCamera& camera, const ObjectFrame& frame,
                                            int num_threads, float scale_modifier) {
  RenderOptions options;
  options.scale_modifier = scale_modifier;
  options.depth = true;
  options.num_threads = num_threads;
  for (float& b : options.background) b = 1.0f;
  options.near_plane = ObjectNearPlane(camera, frame);
  ASSIGN_OR_RETURN(RenderResult render, Render(object, camera, options));
  ViewImages view;
  view.camera = camera;
  view.rgb = std::move(render.color);
  view.alpha = std::move(render.alpha);
  view.mask.resize(view.alpha.size());
  view.depth.assign(view.alpha.size(), 0.0f);
  for (size_t i = 0; i < view.alpha.size(); ++i) {
    view.mask[i] = view.alpha[i] > 0.5f;
    if (view.mask[i]) view.depth[i] = render.median_depth[i];
  }
  return view;
}

std::vector<PinholeCamera> MeshingCameras(const ObjectFrame& frame, const MeshingOptions& options) {
  std::vector<PinholeCamera> cameras;
  RingOptions ring;
  ring.views = options.azimuths;
  ring.size_px = options.size_px;
  ring.focal_px = 280.0 * options.size_px / 256.0;
  for (double elevation : {-60.0, -30.0, 0.0, 30.0, 60.0, 89.0, -89.0}) {
    ring.elevation_deg = elevation;
    if (std::abs(elevation) > 80) ring.views = 1;
    for (const PinholeCamera& c : RingCameras(frame, ring)) cameras.push_back(c);
  }
  return cameras;
}

namespace {

// A view that looks through a hole in a closed shell sees the inner sides of the far walls; those
// depths would mark the object's inside as empty. The depth comes from the surfels that face the
// view; what the view shows at all (alpha, for the carving) from all.
absl::Status DepthFromFacingSurfels(const GaussianCloud& object, const PinholeCamera& camera,
                                    const ObjectFrame& frame, const MeshingOptions& options,
                                    int num_threads, const std::vector<Eigen::Vector3f>& points,
                                    const std::vector<Eigen::Vector3f>& outward,
                                    ViewImages* render) {
  const Eigen::Vector3f eye = camera.CenterInWorld().cast<float>();
  std::vector<uint32_t> facing;
  for (uint32_t g = 0; g < object.size(); ++g) {
    if (outward[g].dot(eye - points[g]) >= 0) facing.push_back(g);
  }
  ASSIGN_OR_RETURN(ViewImages front, RenderObjectView(object.Subset(facing), camera, frame,
                                                      num_threads, options.scale_modifier));
  for (size_t i = 0; i < render->depth.size(); ++i) {
    render->depth[i] = front.alpha[i] > options.min_alpha ? front.depth[i] : 0.0f;
  }
  return absl::OkStatus();
}

// Distance of each empty pixel to the nearest pixel that shows the object. Pinholes and cracks
// between sparse surfels are not views past the object: the shown pixels are closed with a disc
// of empty_close_px (at a 160 px render, scaled with the render size).
std::vector<float> EmptyDistancePx(const PinholeCamera& camera, std::vector<float>& alpha,
                                   const MeshingOptions& options) {
  cv::Mat shown;
  cv::compare(cv::Mat(camera.height, camera.width, CV_32F, alpha.data()), options.empty_alpha,
              shown, cv::CMP_GE);
  const int close = static_cast<int>(std::lround(options.empty_close_px * camera.width / 160.0));
  if (close > 1) {
    cv::morphologyEx(shown, shown, cv::MORPH_CLOSE,
                     cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(close, close)));
  }
  const cv::Mat empty = shown == 0;
  cv::Mat distance;
  cv::distanceTransform(empty, distance, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  return std::vector<float>(distance.begin<float>(), distance.end<float>());
}

// One meshing view's depth (0 where not fused), colour and, for closed meshes, empty distances.
absl::StatusOr<DepthView> MeshingView(const GaussianCloud& object, const PinholeCamera& camera,
                                      const ObjectFrame& frame, const MeshingOptions& options,
                                      int num_threads, const std::vector<Eigen::Vector3f>& points,
                                      const std::vector<Eigen::Vector3f>& outward) {
  ASSIGN_OR_RETURN(ViewImages render,
                   RenderObjectView(object, camera, frame, num_threads, options.scale_modifier));
  if (options.cull_inner_sides) {
    RETURN_IF_ERROR(DepthFromFacingSurfels(object, camera, frame, options, num_threads, points,
                                           outward, &render));
  }
  for (size_t i = 0; i < render.depth.size(); ++i) {
    if (render.alpha[i] <= options.min_alpha) render.depth[i] = 0.0f;  // not fused
  }
  DepthView view{camera, std::move(render.depth), std::move(render.rgb), {}};
  if (options.closed && options.carve_views > 0) {
    view.empty_distance_px = EmptyDistancePx(camera, render.alpha, options);
  }
  return view;
}

// The fusion's voxel and truncations; for closed meshes its bounds (the box of the surfel
// centres, widened by the largest footprint the meshing renders show), the half-space below the
// support and the footprint's inset.
DepthFusionOptions FusionOptions(const GaussianCloud& object, const ObjectFrame& frame,
                                 const MeshingOptions& options,
                                 std::function<bool(const Eigen::Vector3f&)> seen_empty) {
  DepthFusionOptions fusion;
  fusion.voxel = options.voxel_radii * frame.radius;
  fusion.sdf_trunc = 5.0f * fusion.voxel;  // 2DGS's truncation
  fusion.depth_trunc = 3.0f * frame.radius + 2.0f * frame.radius;
  fusion.min_component_triangles = 50;
  fusion.closed_gap_voxels = options.closed_gap_voxels;
  fusion.carve_views = options.closed ? options.carve_views : 0;
  if (!options.closed) return fusion;
  fusion.seen_empty = std::move(seen_empty);
  float widest = 0;
  for (float s : object.log_scales) widest = std::max(widest, std::exp(s));
  for (size_t g = 0; g < object.size(); ++g) {
    fusion.closed_bounds.extend(Eigen::Vector3f(&object.positions[3 * g]));
  }
  const float margin = 2.0f * options.scale_modifier * widest + 2.0f * fusion.voxel;
  fusion.closed_bounds.min().array() -= margin;
  fusion.closed_bounds.max().array() += margin;
  // Nothing of the object lies below its support (nor below its lowest observed point, where
  // the support was estimated above it).
  if (frame.has_support) {
    fusion.outside_below << frame.up, std::min(frame.support_height, frame.bottom_height);
  }
  // The footprint's reach past the true surface: the median surfel sigma as rendered.
  if (options.inset_sigmas > 0 && object.size() > 0) {
    std::vector<float> sigmas(object.size());
    for (size_t g = 0; g < object.size(); ++g) {
      const float* ls = &object.log_scales[object.num_scales * g];
      sigmas[g] = options.scale_modifier * std::exp(std::max(ls[0], ls[1]));
    }
    std::nth_element(sigmas.begin(), sigmas.begin() + sigmas.size() / 2, sigmas.end());
    fusion.inset =
        std::min(options.inset_sigmas * sigmas[sigmas.size() / 2], 0.5f * fusion.sdf_trunc);
  }
  return fusion;
}

// The fused floor stands a fraction of a voxel above the plane it was cut at (the zero crossing
// between the last voxel inside and the first below the plane): the lowest voxel's layer of
// vertices is lowered onto the plane, together.
void LowerFloorOntoSupport(const ObjectFrame& frame, float floor, float voxel, TriangleMesh* mesh) {
  float lowest = std::numeric_limits<float>::infinity();
  for (const Eigen::Vector3f& v : mesh->vertices) lowest = std::min(lowest, frame.up.dot(v));
  const float drop = lowest - floor;
  if (!(drop > 0 && drop <= voxel)) return;
  for (Eigen::Vector3f& v : mesh->vertices) {
    if (frame.up.dot(v) <= lowest + voxel) v -= drop * frame.up;
  }
}

SurfelSnapOptions SnapOptions(const ObjectFrame& frame, const MeshingOptions& options,
                              float voxel) {
  SurfelSnapOptions snap;
  snap.radius = options.snap_radius_spacings * frame.spacing;
  snap.layer = options.snap_layer_spacings * frame.spacing;
  snap.max_move = options.snap_max_voxels * voxel;
  snap.reach = options.snap_reach_spacings * frame.spacing;
  return snap;
}

void SnapMeshToSurfels(const std::vector<Eigen::Vector3f>& points,
                       const std::vector<Eigen::Vector3f>& normals, const ObjectFrame& frame,
                       const MeshingOptions& options, float voxel, const std::vector<uint8_t>& base,
                       TriangleMesh* mesh) {
  SurfelSnapOptions snap = SnapOptions(frame, options, voxel);
  // The base on the support stays flat: it is where the object stands (a sphere's cap, a
  // bottle's foot), and a rounded base rolls in a simulator.
  if (frame.has_support && options.snap_base_across) snap.slide_normal = frame.up;
  SnapToSurfels(points, normals, snap, mesh, base);
}

// Nothing of the mesh stands above the object's highest surfel.
void CapAtHighestSurfel(const GaussianCloud& object, const ObjectFrame& frame, TriangleMesh* mesh) {
  float top = -std::numeric_limits<float>::infinity();
  for (size_t g = 0; g < object.size(); ++g) {
    top = std::max(top, frame.up.dot(Eigen::Vector3f(&object.positions[3 * g])));
  }
  for (Eigen::Vector3f& v : mesh->vertices) {
    const float above = frame.up.dot(v) - top;
    if (above > 0) v -= above * frame.up;
  }
}

// The fused mesh's clean-up on closed meshes: the floor on the support, the vertices snapped to
// the surfels (the base sliding across), the sides within the surfels, the base's ring out to
// where its side meets the support, the top at the highest.
void ShapeClosedMesh(const GaussianCloud& object, const std::vector<Eigen::Vector3f>& points,
                     const std::vector<Eigen::Vector3f>& normals, const ObjectFrame& frame,
                     const MeshingOptions& options, const DepthFusionOptions& fusion,
                     bool clamp_sides, TriangleMesh* mesh) {
  const float floor = std::min(frame.support_height, frame.bottom_height);
  if (frame.has_support && options.base_on_support) {
    LowerFloorOntoSupport(frame, floor, fusion.voxel, mesh);
  }
  // The base: vertices within a voxel of the support (or of the lowest observed point, where the
  // support was estimated above it).
  std::vector<uint8_t> base;
  if (frame.has_support) {
    base.resize(mesh->vertices.size());
    for (size_t v = 0; v < mesh->vertices.size(); ++v) {
      base[v] = frame.up.dot(mesh->vertices[v]) <= floor + fusion.voxel;
    }
  }
  if (options.snap_radius_spacings > 0 && frame.spacing > 0) {
    SnapMeshToSurfels(points, normals, frame, options, fusion.voxel, base, mesh);
  }
  if (clamp_sides && object.size() > 0) ClampToSurfelPolygon(points, frame, mesh);
  if (frame.has_support && options.rim_to_side && frame.spacing > 0) {
    SurfelSnapOptions rim = SnapOptions(frame, options, fusion.voxel);
    rim.slide_normal = frame.up;
    // A side's lowest surfels stand 2-6 mm above the support, a few per 3 spacings of rim.
    rim.radius *= 2;
    ExtendRimToSide(points, normals, rim, mesh, base);
  }
  if (options.top_at_highest_surfel && object.size() > 0) CapAtHighestSurfel(object, frame, mesh);
}

}  // namespace

absl::StatusOr<TriangleMesh> MeshObject(const GaussianCloud& input, const ObjectFrame& frame,
                                        const MeshingOptions& options, int num_threads,
                                        std::function<bool(const Eigen::Vector3f&)> seen_empty,
                                        bool surfels_all_round) {
  GaussianCloud clamped;
  const bool clamp = options.max_scale_spacings > 0 && frame.spacing > 0;
  if (clamp) {
    clamped = input;
    const float limit = std::log(options.max_scale_spacings * frame.spacing);
    for (float& s : clamped.log_scales) s = std::min(s, limit);
  }
  const GaussianCloud& object = clamp ? clamped : input;
  const std::vector<PinholeCamera> cameras = MeshingCameras(frame, options);
  // Each surfel's outer side: the side most of the meshing views' weight sees it from.
  std::vector<Eigen::Vector3f> points, normals, outward;
  SurfelGeometry(object, &points, &normals);
  if (options.cull_inner_sides) {
    ASSIGN_OR_RETURN(outward, OutwardNormals(object, points, normals, frame, cameras, num_threads));
  }
  std::vector<DepthView> views;
  for (const PinholeCamera& camera : cameras) {
    ASSIGN_OR_RETURN(DepthView view,
                     MeshingView(object, camera, frame, options, num_threads, points, outward));
    views.push_back(std::move(view));
  }
  const DepthFusionOptions fusion = FusionOptions(object, frame, options, std::move(seen_empty));
  ASSIGN_OR_RETURN(TriangleMesh mesh, FuseDepthMaps(views, fusion));
  if (!options.closed) return mesh;
  // Where the renders' visual hull closed what the surfels leave open (an unseen back), the
  // surface stands past the surfels by right: the clamp would cut it. Not where the surfels stand
  // all round the object.
  const bool clamp_sides =
      options.sides_within_surfels && (!fusion.seen_empty || surfels_all_round);
  ShapeClosedMesh(object, points, normals, frame, options, fusion, clamp_sides, &mesh);
  return mesh;
}

}  // namespace instascene::generation
