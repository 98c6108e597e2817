// services/objects/query_index.h: click queries against a segmentation result.
//
// The index renders each view's instance label map once (per pixel, the label with the largest
// summed blending weight; all at build, or each on the first click in its view) and keeps
// per-instance Gaussian lists, so a click (view, pixel) is a lookup, and a 3D point query is a k-d
// tree nearest-neighbour search over the labelled Gaussians.
// The scene and cloud passed to Build must outlive the index. Build is not thread-safe; queries are
// const and safe from many threads.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "common/eval/result.h"
#include "common/geometry/point_index.h"
#include "common/scene/scene.h"

namespace instascene::objects {

struct QueryAnswer {
  uint32_t instance = 0;                      // 0 = background / nothing
  size_t gaussians = 0;                       // Gaussians of that instance
  std::vector<std::pair<int, size_t>> views;  // (view, pixels) where the instance is visible
};

class QueryIndex {
 public:
  // eager: render every view's label map now (and know each instance's visible views, in
  // QueryAnswer::views); otherwise each map is rendered on the first click in its view (a
  // service's cold start then costs no rendering; answers carry no views).
  static absl::StatusOr<std::unique_ptr<QueryIndex>> Build(const Scene& scene,
                                                           const GaussianCloud& cloud,
                                                           const SegmentationResult& result,
                                                           int num_threads = 0, bool eager = true);

  // The instance under pixel (x, y) of view `view`.
  absl::StatusOr<QueryAnswer> Click(int view, int x, int y) const;
  // The instance nearest to a 3D point (its nearest labelled Gaussian), if within max_distance.
  absl::StatusOr<QueryAnswer> Point(const Eigen::Vector3f& point_in_world,
                                    float max_distance) const;
  // The instance a ray meets: the label with the largest summed blending weight along the ray
  // (rendered through a one-pixel camera at the origin looking along the direction).
  absl::StatusOr<QueryAnswer> Ray(const Eigen::Vector3f& origin_in_world,
                                  const Eigen::Vector3f& direction) const;
  // The instance's mask in a view (W*H, 1 = selected).
  std::vector<uint8_t> Mask(uint32_t instance, int view) const;
  const std::vector<uint32_t>& Gaussians(uint32_t instance) const;
  // Every instance with at least one Gaussian, ascending.
  std::vector<uint32_t> Instances() const;
  // Approximate memory held: label maps, labels, members, the k-d tree.
  size_t ByteSize() const;

 private:
  QueryAnswer Answer(uint32_t instance) const;
  // A view's label map, rendered once on first use (thread-safe).
  absl::StatusOr<const std::vector<uint32_t>*> LabelMap(int view) const;
  struct LazyView {
    std::once_flag once;
    std::vector<uint32_t> map;  // W*H
    absl::Status status;
  };
  const Scene* scene_ = nullptr;
  const GaussianCloud* cloud_ = nullptr;
  std::vector<std::unique_ptr<LazyView>> views_;
  int num_threads_ = 0;
  std::map<uint32_t, std::vector<uint32_t>> members_;                // instance -> Gaussians
  std::map<uint32_t, std::vector<std::pair<int, size_t>>> visible_;  // instance -> (view, pixels)
  std::vector<uint32_t> labels_;
  std::unique_ptr<PointIndex3> points_;  // labelled Gaussians only
  std::vector<uint32_t> point_labels_;   // their labels
};

}  // namespace instascene::objects
