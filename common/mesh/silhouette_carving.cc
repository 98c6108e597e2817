#include "common/mesh/silhouette_carving.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <functional>

namespace instascene {
namespace {

// The views that carve (those with empty distances), each with its pixel-homogeneous projection
// (u z, v z, z) = K (R p + t), affine in p.
struct CarvingView {
  const DepthView* view;
  Eigen::Matrix<double, 3, 4> projection;
};

std::vector<CarvingView> CarvingViews(const std::vector<DepthView>& views) {
  std::vector<CarvingView> carving;
  for (const DepthView& view : views) {
    if (view.empty_distance_px.empty()) continue;
    const PinholeCamera& c = view.camera;
    Eigen::Matrix3d k;
    k << c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1;
    Eigen::Matrix<double, 3, 4> m;
    m.leftCols<3>() = k * c.camera_from_world.rotation.cast<double>();
    m.col(3) = k * c.camera_from_world.translation.cast<double>();
    carving.push_back({&view, m});
  }
  return carving;
}

// One voxel's outside distances (in truncations) from the views whose pixel at it is empty, and
// how many views show the object there; q[i] is the voxel in view i's homogeneous pixels.
size_t VoxelDistances(const std::vector<CarvingView>& carving,
                      const std::vector<Eigen::Vector3d>& q, double sdf_trunc,
                      std::vector<float>* distances) {
  distances->clear();
  size_t shown = 0;
  for (size_t i = 0; i < carving.size(); ++i) {
    if (!(q[i].z() > 0)) continue;
    const PinholeCamera& c = carving[i].view->camera;
    const double u = q[i].x() / q[i].z(), v = q[i].y() / q[i].z();
    if (!(u >= 0 && v >= 0 && u < c.width && v < c.height)) continue;
    const float d =
        carving[i]
            .view->empty_distance_px[static_cast<size_t>(v) * c.width + static_cast<size_t>(u)];
    if (d > 0) {
      distances->push_back(static_cast<float>(d * q[i].z() / c.fx / sdf_trunc));
    } else {
      ++shown;
    }
  }
  return shown;
}

}  // namespace

void CarveSilhouettes(const std::vector<DepthView>& views, int carve_views, double sdf_trunc,
                      open3d::pipelines::integration::UniformTSDFVolume* volume,
                      const std::function<bool(const Eigen::Vector3f&)>& seen_empty,
                      std::vector<uint8_t>* in_hull) {
  const int n = volume->resolution_;
  const double voxel = volume->voxel_length_;
  const std::vector<CarvingView> carving = CarvingViews(views);
  if (static_cast<int>(carving.size()) < carve_views) return;
  if (in_hull != nullptr) in_hull->assign(volume->voxels_.size(), 0);
  // Each voxel is independent: parallel over x slabs, the same result for any thread count.
  tbb::parallel_for(0, n, [&](int x) {
    std::vector<float> distances;
    distances.reserve(carving.size());
    std::vector<Eigen::Vector3d> start(carving.size()), q(carving.size());
    for (int y = 0; y < n; ++y) {
      const Eigen::Vector3d p0 = volume->origin_ + voxel * Eigen::Vector3d(x + 0.5, y + 0.5, 0.5);
      for (size_t i = 0; i < carving.size(); ++i) {
        start[i] = carving[i].projection.leftCols<3>() * p0 + carving[i].projection.col(3);
      }
      for (int z = 0; z < n; ++z) {
        open3d::geometry::TSDFVoxel& voxel_value = volume->voxels_[volume->IndexOf(x, y, z)];
        // Observed free space (the views' truncated +1) cannot be raised further.
        if (voxel_value.weight_ > 0 && voxel_value.tsdf_ >= 1.0f) continue;
        for (size_t i = 0; i < carving.size(); ++i) {
          q[i] = start[i] + (z * voxel) * carving[i].projection.col(2);
        }
        const size_t shown = VoxelDistances(carving, q, sdf_trunc, &distances);
        // Unobserved, shown by every view, not seen empty by the capture: inside.
        if (in_hull != nullptr && shown == carving.size() && voxel_value.weight_ <= 0 &&
            !seen_empty((p0 + (z * voxel) * Eigen::Vector3d::UnitZ()).cast<float>())) {
          (*in_hull)[volume->IndexOf(x, y, z)] = 1;
        }
        if (static_cast<int>(distances.size()) < carve_views) continue;
        std::nth_element(distances.begin(), distances.begin() + (carve_views - 1), distances.end(),
                         std::greater<float>());
        const float carve = std::min(1.0f, distances[carve_views - 1]);
        if (voxel_value.weight_ <= 0) {
          voxel_value.tsdf_ = carve;
          voxel_value.weight_ = 1.0f;
        } else {
          voxel_value.tsdf_ = std::max(voxel_value.tsdf_, carve);
        }
      }
    }
  });
}

}  // namespace instascene
