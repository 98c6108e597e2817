#include "services/generation/candidate_filter.h"

#include <algorithm>

namespace instascene::generation {
namespace {

int64_t CellKey(const Eigen::Vector3i& c) {
  return ((static_cast<int64_t>(c.x()) & 0x1FFFFF) << 42) |
         ((static_cast<int64_t>(c.y()) & 0x1FFFFF) << 21) |
         (static_cast<int64_t>(c.z()) & 0x1FFFFF);
}

}  // namespace

CandidateFilter::CandidateFilter(const ObjectFrame& frame, const PointIndex3& observed,
                                 const ObservedSurface& observed_surface,
                                 const FreeSpaceGrid& free_space,
                                 const SeenThroughTest* seen_through,
                                 const GeometricPriorOptions& options)
    : frame_(frame),
      observed_(observed),
      observed_surface_(observed_surface),
      free_space_(free_space),
      seen_through_(seen_through),
      options_(options),
      cover_(options.cover_spacings * std::max(frame.spacing, 1e-6f)) {}

void CandidateFilter::Consider(const SurfelCandidate& c) {
  if (frame_.has_support &&
      frame_.up.dot(c.position) < frame_.support_height - 0.5f * frame_.spacing) {
    ++rejected_.below_support;
    return;
  }
  if (free_space_.FreeViews(c.position) >= options_.candidate_free_views) {
    ++rejected_.observed_free;
    return;
  }
  if (observed_.Nearest(c.position).second <= cover_ * cover_ || Covered(c.position)) {
    ++rejected_.already_covered;
    return;
  }
  if (observed_surface_.Contradicts(c.position)) {
    ++rejected_.off_observed_surface;
    return;
  }
  // The exact test last (a few rays per real view): the grid is coarse and its margin keeps
  // 1.5 voxels in front of every surface uncarved.
  if (options_.exact_free_space && seen_through_ != nullptr &&
      seen_through_->SeenThrough(c.position)) {
    ++rejected_.observed_free;
    return;
  }
  cells_[CellKey(Cell(c.position))].push_back(c.position);
  added_.push_back(c);
}

Eigen::Vector3i CandidateFilter::Cell(const Eigen::Vector3f& p) const {
  return (p / cover_).array().floor().cast<int>();
}

bool CandidateFilter::Covered(const Eigen::Vector3f& p) const {
  const Eigen::Vector3i c = Cell(p);
  for (int dz = -1; dz <= 1; ++dz) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const auto it = cells_.find(CellKey(c + Eigen::Vector3i(dx, dy, dz)));
        if (it == cells_.end()) continue;
        for (const Eigen::Vector3f& q : it->second) {
          if ((q - p).squaredNorm() <= cover_ * cover_) return true;
        }
      }
    }
  }
  return false;
}

}  // namespace instascene::generation
