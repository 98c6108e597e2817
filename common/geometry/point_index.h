// common/geometry/point_index.h: a k-d tree over 3D points (nanoflann), for nearest-neighbour and
// radius queries (Chamfer distance, DBSCAN, 1-NN label transfer). Holds a copy of the points.
// Build once; queries are const and safe from many threads.
#pragma once

#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include <Eigen/Core>

namespace instascene {

class PointIndex3 {
 public:
  explicit PointIndex3(std::vector<Eigen::Vector3f> points);
  ~PointIndex3();
  PointIndex3(const PointIndex3&) = delete;
  PointIndex3& operator=(const PointIndex3&) = delete;

  size_t size() const { return points_.size(); }
  const std::vector<Eigen::Vector3f>& points() const { return points_; }

  // Index of and squared distance to the nearest point; the index is size() when empty.
  std::pair<uint32_t, float> Nearest(const Eigen::Vector3f& query) const;
  // The k nearest points (fewer when the index is smaller) as (index, squared distance), nearest
  // first; ties broken by index.
  std::vector<std::pair<uint32_t, float>> KNearest(const Eigen::Vector3f& query, size_t k) const;
  // Indices of all points within `radius` (inclusive), in increasing index order.
  std::vector<uint32_t> WithinRadius(const Eigen::Vector3f& query, float radius) const;

 private:
  struct Tree;
  std::vector<Eigen::Vector3f> points_;
  std::unique_ptr<Tree> tree_;
};

}  // namespace instascene
