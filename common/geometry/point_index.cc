#include "common/geometry/point_index.h"

#include <algorithm>

#include <nanoflann.hpp>

namespace instascene {

// nanoflann dataset adaptor over the owned points.
struct PointIndex3::Tree {
  struct Adaptor {
    const std::vector<Eigen::Vector3f>* points;
    size_t kdtree_get_point_count() const { return points->size(); }
    float kdtree_get_pt(size_t i, size_t dim) const { return (*points)[i][static_cast<int>(dim)]; }
    template <class BBox>
    bool kdtree_get_bbox(BBox&) const {
      return false;
    }
  };
  using Index = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, Adaptor>,
                                                    Adaptor, 3, uint32_t>;
  explicit Tree(const std::vector<Eigen::Vector3f>* points)
      : adaptor{points}, index(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16)) {
    index.buildIndex();
  }
  Adaptor adaptor;
  Index index;
};

PointIndex3::PointIndex3(std::vector<Eigen::Vector3f> points)
    : points_(std::move(points)), tree_(std::make_unique<Tree>(&points_)) {}

PointIndex3::~PointIndex3() = default;

std::pair<uint32_t, float> PointIndex3::Nearest(const Eigen::Vector3f& query) const {
  if (points_.empty()) return {0, 0.0f};
  uint32_t index = 0;
  float dist_sq = 0.0f;
  nanoflann::KNNResultSet<float, uint32_t> result(1);
  result.init(&index, &dist_sq);
  tree_->index.findNeighbors(result, query.data(), nanoflann::SearchParams());
  return {index, dist_sq};
}

std::vector<std::pair<uint32_t, float>> PointIndex3::KNearest(const Eigen::Vector3f& query,
                                                              size_t k) const {
  k = std::min(k, points_.size());
  std::vector<uint32_t> indices(k);
  std::vector<float> dist_sq(k);
  if (k > 0) {
    nanoflann::KNNResultSet<float, uint32_t> result(k);
    result.init(indices.data(), dist_sq.data());
    tree_->index.findNeighbors(result, query.data(), nanoflann::SearchParams());
  }
  std::vector<std::pair<uint32_t, float>> out(k);
  for (size_t i = 0; i < k; ++i) out[i] = {indices[i], dist_sq[i]};
  std::stable_sort(out.begin(), out.end(), [](const auto& a, const auto& b) {
    return a.second < b.second || (a.second == b.second && a.first < b.first);
  });
  return out;
}

std::vector<uint32_t> PointIndex3::WithinRadius(const Eigen::Vector3f& query, float radius) const {
  std::vector<std::pair<uint32_t, float>> matches;
  if (!points_.empty()) {
    // nanoflann's L2 adaptor works in squared distances.
    tree_->index.radiusSearch(query.data(), radius * radius, matches, nanoflann::SearchParams());
  }
  std::vector<uint32_t> out;
  out.reserve(matches.size());
  for (const auto& m : matches) out.push_back(m.first);
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace instascene
