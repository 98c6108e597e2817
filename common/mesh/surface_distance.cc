#include "common/mesh/surface_distance.h"

#include <open3d/core/Tensor.h>
#include <open3d/t/geometry/RaycastingScene.h>

#include "absl/strings/str_cat.h"

namespace instascene {

SurfaceDistance::SurfaceDistance() = default;
SurfaceDistance::~SurfaceDistance() = default;

absl::StatusOr<std::unique_ptr<SurfaceDistance>> SurfaceDistance::Create(const TriangleMesh& mesh) {
  if (mesh.triangles.empty()) return absl::InvalidArgumentError("surface distance: no triangles");
  const int64_t nv = static_cast<int64_t>(mesh.vertices.size());
  const int64_t nt = static_cast<int64_t>(mesh.triangles.size());
  std::vector<float> vertices(3 * nv);
  for (int64_t i = 0; i < nv; ++i) {
    for (int k = 0; k < 3; ++k) vertices[3 * i + k] = mesh.vertices[i][k];
  }
  std::vector<uint32_t> triangles(3 * nt);
  for (int64_t t = 0; t < nt; ++t) {
    for (int k = 0; k < 3; ++k) {
      if (mesh.triangles[t][k] >= mesh.vertices.size()) {
        return absl::InvalidArgumentError(absl::StrCat("surface distance: triangle ", t,
                                                       " indexes vertex ", mesh.triangles[t][k],
                                                       " of ", nv));
      }
      triangles[3 * t + k] = mesh.triangles[t][k];
    }
  }
  using open3d::core::Tensor;
  std::unique_ptr<SurfaceDistance> d(new SurfaceDistance());
  d->scene_ = std::make_unique<open3d::t::geometry::RaycastingScene>();
  d->scene_->AddTriangles(Tensor(vertices, {nv, 3}, open3d::core::Float32),
                          Tensor(triangles, {nt, 3}, open3d::core::UInt32));
  return d;
}

std::vector<float> SurfaceDistance::Distances(const std::vector<Eigen::Vector3f>& points) const {
  if (points.empty()) return {};
  const int64_t n = static_cast<int64_t>(points.size());
  std::vector<float> query(3 * n);
  for (int64_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) query[3 * i + k] = points[i][k];
  }
  std::lock_guard<std::mutex> lock(mutex_);
  const open3d::core::Tensor distances =
      scene_->ComputeDistance(open3d::core::Tensor(query, {n, 3}, open3d::core::Float32));
  const float* data = distances.GetDataPtr<float>();
  return std::vector<float>(data, data + n);
}

}  // namespace instascene
