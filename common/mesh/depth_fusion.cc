#include "common/mesh/depth_fusion.h"

#include <open3d/camera/PinholeCameraIntrinsic.h>
#include <open3d/geometry/Image.h>
#include <open3d/geometry/RGBDImage.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/pipelines/integration/ScalableTSDFVolume.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <exception>
#include <numeric>

#include "absl/strings/str_cat.h"

namespace instascene {
namespace {

absl::Status CheckInputs(const std::vector<DepthView>& views, const DepthFusionOptions& options) {
  if (!(options.voxel > 0) || !(options.depth_trunc > 0) || options.sdf_trunc < 0 ||
      !std::isfinite(options.voxel) || !std::isfinite(options.depth_trunc)) {
    return absl::InvalidArgumentError("depth fusion: voxel and depth_trunc must be positive");
  }
  for (size_t v = 0; v < views.size(); ++v) {
    const PinholeCamera& camera = views[v].camera;
    if (absl::Status s = camera.Validate(); !s.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("depth fusion view ", v, ": ", s.message()));
    }
    const size_t pixels = static_cast<size_t>(camera.width) * camera.height;
    if (views[v].depth.size() != pixels ||
        (!views[v].color.empty() && views[v].color.size() != 3 * pixels)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "depth fusion view ", v, ": buffers do not match ", camera.width, "x", camera.height));
    }
  }
  return absl::OkStatus();
}

void Integrate(const DepthView& view, float depth_trunc,
               open3d::pipelines::integration::ScalableTSDFVolume* volume) {
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
    open3d::pipelines::integration::ScalableTSDFVolume volume(
        options.voxel, sdf_trunc, open3d::pipelines::integration::TSDFVolumeColorType::RGB8);
    for (const DepthView& view : views) Integrate(view, options.depth_trunc, &volume);
    std::shared_ptr<open3d::geometry::TriangleMesh> fused = volume.ExtractTriangleMesh();
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
