#include "common/mesh/depth_fusion.h"

#include <open3d/camera/PinholeCameraIntrinsic.h>
#include <open3d/geometry/Image.h>
#include <open3d/geometry/RGBDImage.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/pipelines/integration/ScalableTSDFVolume.h>
#include <open3d/pipelines/integration/UniformTSDFVolume.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <exception>
#include <numeric>
#include <vector>

#include "absl/strings/str_cat.h"
#include "common/mesh/silhouette_carving.h"

namespace instascene {
namespace {

absl::Status CheckInputs(const std::vector<DepthView>& views, const DepthFusionOptions& options) {
  if (!(options.voxel > 0) || !(options.depth_trunc > 0) || options.sdf_trunc < 0 ||
      !std::isfinite(options.voxel) || !std::isfinite(options.depth_trunc)) {
    return absl::InvalidArgumentError("depth fusion: voxel and depth_trunc must be positive");
  }
  if (!options.closed_bounds.isEmpty() &&
      (!options.closed_bounds.sizes().allFinite() || options.max_closed_resolution < 8 ||
       options.max_closed_resolution > 512 || options.closed_gap_voxels < 0 ||
       options.closed_gap_voxels > 32 || !options.outside_below.allFinite() ||
       options.carve_views < 0)) {
    return absl::InvalidArgumentError(
        "depth fusion: closed bounds and support plane must be finite, max_closed_resolution in "
        "[8, 512], closed_gap_voxels in [0, 32], carve_views >= 0");
  }
  const double sdf_trunc = options.sdf_trunc > 0 ? options.sdf_trunc : 5.0 * options.voxel;
  if (!(options.inset >= 0) || !(options.inset <= 0.5 * sdf_trunc)) {
    return absl::InvalidArgumentError(absl::StrCat("depth fusion: inset ", options.inset,
                                                   " is not in [0, half the truncation band ",
                                                   0.5 * sdf_trunc, "]"));
  }
  for (size_t v = 0; v < views.size(); ++v) {
    const PinholeCamera& camera = views[v].camera;
    if (absl::Status s = camera.Validate(); !s.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("depth fusion view ", v, ": ", s.message()));
    }
    const size_t pixels = static_cast<size_t>(camera.width) * camera.height;
    if (views[v].depth.size() != pixels ||
        (!views[v].color.empty() && views[v].color.size() != 3 * pixels) ||
        (!views[v].empty_distance_px.empty() && views[v].empty_distance_px.size() != pixels)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "depth fusion view ", v, ": buffers do not match ", camera.width, "x", camera.height));
    }
  }
  return absl::OkStatus();
}

void Integrate(const DepthView& view, float depth_trunc,
               open3d::pipelines::integration::TSDFVolume* volume) {
  using open3d::geometry::Image;
  const PinholeCamera& camera = view.camera;
  const int w = camera.width, h = camera.height;
  Image color, depth;
  color.Prepare(w, h, 3, 1);
  depth.Prepare(w, h, 1, 4);
  auto* depth_px = depth.PointerAs<float>();
  for (int i = 0; i < w * h; ++i) {
    const float d = view.depth[i];
    depth_px[i] = std::isfinite(d) && d > 0 ? d : 0.0f;
    for (int c = 0; c < 3; ++c) {
      const float value = view.color.empty() ? 0.5f : view.color[3 * i + c];
      color.data_[3 * i + c] =
          static_cast<uint8_t>(std::lround(std::clamp(value, 0.0f, 1.0f) * 255.0f));
    }
  }
  auto rgbd =
      open3d::geometry::RGBDImage::CreateFromColorAndDepth(color, depth, 1.0, depth_trunc, false);
  // Open3D puts pixel centres at integer coordinates; this project at +0.5 (COLMAP).
  const open3d::camera::PinholeCameraIntrinsic intrinsic(w, h, camera.fx, camera.fy,
                                                         camera.cx - 0.5, camera.cy - 0.5);
  Eigen::Matrix4d extrinsic = Eigen::Matrix4d::Identity();
  extrinsic.topLeftCorner<3, 3>() = camera.camera_from_world.rotation;
  extrinsic.topRightCorner<3, 1>() = camera.camera_from_world.translation;
  volume->Integrate(*rgbd, intrinsic, extrinsic);
}

// The n^3 voxel lattice of a UniformTSDFVolume (index x * n * n + y * n + z).
struct Lattice {
  int n;

  template <typename Visit>
  void ForNeighbours(int i, Visit&& visit) const {
    const int x = i / (n * n), y = (i / n) % n, z = i % n;
    if (x > 0) visit(i - n * n);
    if (x + 1 < n) visit(i + n * n);
    if (y > 0) visit(i - n);
    if (y + 1 < n) visit(i + n);
    if (z > 0) visit(i - 1);
    if (z + 1 < n) visit(i + 1);
  }
  bool OnBorder(int i) const {
    const int x = i / (n * n), y = (i / n) % n, z = i % n;
    return x == 0 || y == 0 || z == 0 || x == n - 1 || y == n - 1 || z == n - 1;
  }
  // Breadth-first steps from the marked voxels of `reached` through voxels `may_enter` admits,
  // at most `steps` deep (all when negative); marks what it reaches.
  template <typename MayEnter>
  void Spread(int steps, MayEnter&& may_enter, std::vector<uint8_t>* reached) const {
    std::vector<int> queue, next;
    for (size_t i = 0; i < reached->size(); ++i) {
      if ((*reached)[i]) queue.push_back(static_cast<int>(i));
    }
    for (int step = 0; !queue.empty() && step != steps; ++step) {
      next.clear();
      for (int i : queue) {
        ForNeighbours(i, [&](int j) {
          if (!(*reached)[j] && may_enter(j)) {
            (*reached)[j] = 1;
            next.push_back(j);
          }
        });
      }
      queue.swap(next);
    }
  }
};

// What the grid's border reaches through passable voxels farther than `gap` voxels from a
// blocked one, grown back by `gap` through passable voxels (an opening).
template <typename Blocked>
std::vector<uint8_t> OutsideVoxels(const Lattice& lattice, size_t count, int gap,
                                   Blocked&& blocked) {
  std::vector<uint8_t> near_block(count, 0);
  for (size_t i = 0; i < count; ++i) near_block[i] = blocked(i);
  lattice.Spread(
      gap, [](int) { return true; }, &near_block);
  std::vector<uint8_t> outside(count, 0);
  for (size_t i = 0; i < count; ++i) outside[i] = lattice.OnBorder(static_cast<int>(i));
  lattice.Spread(
      -1, [&](int j) { return !near_block[j]; }, &outside);
  lattice.Spread(
      gap, [&](int j) { return !blocked(j); }, &outside);
  return outside;
}

// Unobserved voxels take the colour of the nearest observed one (breadth first).
void SpreadColours(const Lattice& lattice, const std::vector<uint8_t>& observed,
                   std::vector<open3d::geometry::TSDFVoxel>* voxels) {
  std::vector<uint8_t> coloured = observed;
  std::vector<int> queue;
  for (size_t i = 0; i < observed.size(); ++i) {
    if (observed[i]) queue.push_back(static_cast<int>(i));
  }
  for (size_t head = 0; head < queue.size(); ++head) {
    const Eigen::Vector3d color = (*voxels)[queue[head]].color_;
    lattice.ForNeighbours(queue[head], [&](int j) {
      if (!coloured[j]) {
        coloured[j] = 1;
        (*voxels)[j].color_ = color;
        queue.push_back(j);
      }
    });
  }
}

// Gives every voxel of `volume` a value (see DepthFusionOptions::closed_bounds). A voxel is
// blocked when it lies behind an observed surface (tsdf <= 0), passable otherwise (unobserved, or
// in front of a surface). The outside is what the grid's border reaches through passable voxels
// farther than `gap` voxels from a blocked one (so the flood does not leak through holes up to
// 2 * gap voxels wide), grown back by `gap` through passable voxels (an opening). Passable
// voxels outside become +1 when unobserved; the rest of the passable voxels are enclosed (the
// unobserved inside, pockets seen from within through a hole) and become -1; the border is +1.
// Filled voxels take the colour of the nearest observed one (breadth first).
void CloseVolume(int gap, const std::vector<uint8_t>& in_hull,
                 open3d::pipelines::integration::UniformTSDFVolume* volume) {
  const Lattice lattice{volume->resolution_};
  std::vector<open3d::geometry::TSDFVoxel>& voxels = volume->voxels_;
  const size_t count = voxels.size();
  // Behind an observed surface, or unobserved inside the renders' visual hull.
  auto blocked = [&](size_t i) {
    return (voxels[i].weight_ > 0 && voxels[i].tsdf_ <= 0) || (!in_hull.empty() && in_hull[i]);
  };
  const std::vector<uint8_t> outside = OutsideVoxels(lattice, count, gap, blocked);
  std::vector<uint8_t> observed(count, 0);
  for (size_t i = 0; i < count; ++i) {
    observed[i] = voxels[i].weight_ > 0;
    if (lattice.OnBorder(static_cast<int>(i))) {
      voxels[i].tsdf_ = 1.0f;
      voxels[i].weight_ = 1.0f;
    } else if ((!blocked(i) || !observed[i]) && !outside[i]) {
      voxels[i].tsdf_ = -1.0f;  // enclosed (or unobserved inside the visual hull)
      voxels[i].weight_ = 1.0f;
    } else if (!observed[i]) {
      voxels[i].tsdf_ = 1.0f;  // the outside no view looked into
      voxels[i].weight_ = 1.0f;
    }
  }
  SpreadColours(lattice, observed, &voxels);
}

// Below the plane n·p = d (outside_below = (n, d)) every voxel is outside, whatever the visual
// hull says: the renders show the object's underside there, and the capture could not see under
// the table.
void MarkOutsideBelow(const Eigen::Vector4f& outside_below, double voxel,
                      open3d::pipelines::integration::UniformTSDFVolume* volume,
                      std::vector<uint8_t>* in_hull) {
  const Eigen::Vector3d normal = outside_below.head<3>().cast<double>();
  const Eigen::Vector3d origin = volume->origin_;
  const int resolution = volume->resolution_;
  for (int x = 0; x < resolution; ++x) {
    for (int y = 0; y < resolution; ++y) {
      for (int z = 0; z < resolution; ++z) {
        const Eigen::Vector3d p = origin + voxel * Eigen::Vector3d(x + 0.5, y + 0.5, z + 0.5);
        if (normal.dot(p) >= outside_below[3]) continue;
        const int i = volume->IndexOf(x, y, z);
        open3d::geometry::TSDFVoxel& v = volume->voxels_[i];
        v.tsdf_ = 1.0f;
        v.weight_ = std::max(v.weight_, 1.0f);
        if (!in_hull->empty()) (*in_hull)[i] = 0;
      }
    }
  }
}

std::shared_ptr<open3d::geometry::TriangleMesh> FuseClosed(const std::vector<DepthView>& views,
                                                           const DepthFusionOptions& options,
                                                           double sdf_trunc) {
  const Eigen::Vector3d center = options.closed_bounds.center().cast<double>();
  // The cube around the box, with room for the truncation band and an outside border.
  const double side = options.closed_bounds.sizes().maxCoeff() + 2.0 * sdf_trunc;
  const double cells = std::ceil(side / options.voxel) + 4;  // may be huge: compared as double
  int resolution = options.max_closed_resolution;
  double voxel = side / (resolution - 4);
  if (cells <= options.max_closed_resolution) {
    resolution = static_cast<int>(cells);
    voxel = options.voxel;
  }
  const double length = voxel * resolution;
  open3d::pipelines::integration::UniformTSDFVolume volume(
      length, resolution, sdf_trunc, open3d::pipelines::integration::TSDFVolumeColorType::RGB8,
      center - Eigen::Vector3d::Constant(0.5 * length));
  for (const DepthView& view : views) Integrate(view, options.depth_trunc, &volume);
  std::vector<uint8_t> in_hull;
  if (options.carve_views > 0) {
    CarveSilhouettes(views, options.carve_views, sdf_trunc, &volume, options.seen_empty,
                     options.seen_empty ? &in_hull : nullptr);
  }
  if (!options.outside_below.isZero()) {
    MarkOutsideBelow(options.outside_below, voxel, &volume, &in_hull);
  }
  CloseVolume(options.closed_gap_voxels, in_hull, &volume);
  // The inset shifts the zero level: the fused TSDF is projective (distances along each view's
  // rays), steeper across the surface than 1 / sdf_trunc wherever views met it obliquely, so the
  // surface moves by `inset` where views met it head-on and less elsewhere.
  if (options.inset > 0) {
    const float shift = static_cast<float>(options.inset / sdf_trunc);
    for (open3d::geometry::TSDFVoxel& v : volume.voxels_) {
      v.tsdf_ = std::clamp(v.tsdf_ + shift, -1.0f, 1.0f);
    }
  }
  return volume.ExtractTriangleMesh();
}

// 2DGS post_process_mesh: keep the largest components.
void KeepLargestComponents(const DepthFusionOptions& options,
                           open3d::geometry::TriangleMesh* mesh) {
  auto [cluster_of_triangle, triangles_per_cluster, area] = mesh->ClusterConnectedTriangles();
  std::vector<size_t> order(triangles_per_cluster.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return triangles_per_cluster[a] > triangles_per_cluster[b];
  });
  std::vector<bool> keep(order.size(), false);
  for (size_t rank = 0; rank < order.size() && rank < static_cast<size_t>(options.keep_components);
       ++rank) {
    keep[order[rank]] =
        triangles_per_cluster[order[rank]] >= static_cast<size_t>(options.min_component_triangles);
  }
  std::vector<bool> remove(cluster_of_triangle.size());
  for (size_t t = 0; t < remove.size(); ++t) remove[t] = !keep[cluster_of_triangle[t]];
  mesh->RemoveTrianglesByMask(remove);
  mesh->RemoveUnreferencedVertices();
}

}  // namespace

absl::StatusOr<TriangleMesh> FuseDepthMaps(const std::vector<DepthView>& views,
                                           const DepthFusionOptions& options) {
  if (absl::Status s = CheckInputs(views, options); !s.ok()) return s;
  const double sdf_trunc = options.sdf_trunc > 0 ? options.sdf_trunc : 5.0 * options.voxel;
  try {
    std::shared_ptr<open3d::geometry::TriangleMesh> fused;
    if (!options.closed_bounds.isEmpty()) {
      fused = FuseClosed(views, options, sdf_trunc);
    } else {
      open3d::pipelines::integration::ScalableTSDFVolume volume(
          options.voxel, sdf_trunc, open3d::pipelines::integration::TSDFVolumeColorType::RGB8);
      for (const DepthView& view : views) Integrate(view, options.depth_trunc, &volume);
      fused = volume.ExtractTriangleMesh();
    }
    KeepLargestComponents(options, fused.get());
    TriangleMesh mesh;
    mesh.vertices.reserve(fused->vertices_.size());
    for (const Eigen::Vector3d& v : fused->vertices_) mesh.vertices.push_back(v.cast<float>());
    if (fused->vertex_colors_.size() == fused->vertices_.size()) {
      for (const Eigen::Vector3d& c : fused->vertex_colors_) mesh.colors.push_back(c.cast<float>());
    }
    mesh.triangles.reserve(fused->triangles_.size());
    for (const Eigen::Vector3i& t : fused->triangles_) {
      mesh.triangles.push_back(
          {static_cast<uint32_t>(t[0]), static_cast<uint32_t>(t[1]), static_cast<uint32_t>(t[2])});
    }
    return mesh;
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError("depth fusion: out of memory");
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat("depth fusion (open3d): ", e.what()));
  }
}

}  // namespace instascene
