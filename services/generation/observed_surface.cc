#include "services/generation/observed_surface.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"

namespace instascene::generation {

absl::Status ObservedSurfaceOptions::Validate() const {
  if (!(front_spacings >= 0) || !(front_spacings <= 100) || !(behind_spacings >= 0) ||
      !(behind_spacings <= 100) || !(lateral_spacings > 0) || !(lateral_spacings <= 100)) {
    return absl::InvalidArgumentError(
        absl::StrCat("observed surface options out of range (front_spacings ", front_spacings,
                     " and behind_spacings ", behind_spacings, " in [0, 100], lateral_spacings ",
                     lateral_spacings, " in (0, 100])"));
  }
  return absl::OkStatus();
}

std::vector<Eigen::Vector3f> SeenSideNormals(const std::vector<Eigen::Vector3f>& points,
                                             const std::vector<Eigen::Vector3f>& normals,
                                             const SeenThroughTest* seen,
                                             const Eigen::Vector3f& center) {
  std::vector<Eigen::Vector3f> out(normals.size());
  for (size_t g = 0; g < normals.size(); ++g) {
    const Eigen::Vector3f& n = normals[g];
    int side = seen != nullptr ? seen->SeenSide(points[g], n) : 0;
    if (side == 0) side = n.dot(points[g] - center) < 0 ? -1 : 1;
    out[g] = static_cast<float>(side) * n;
  }
  return out;
}

ObservedSurface::ObservedSurface(const PointIndex3* index,
                                 const std::vector<Eigen::Vector3f>& normals,
                                 const SeenThroughTest* seen, const Eigen::Vector3f& center,
                                 float spacing, const ObservedSurfaceOptions& options)
    : index_(options.front_spacings > 0 ? index : nullptr) {
  if (index_ == nullptr) return;  // off: no rays for the normals' sides
  seen_normals_ = SeenSideNormals(index_->points(), normals, seen, center);
  const float s = std::max(spacing, 1e-6f);
  front_ = options.front_spacings * s;
  // No behind test: -infinity never passes `along < -behind_`.
  behind_ = options.behind_spacings > 0 ? options.behind_spacings * s
                                        : std::numeric_limits<float>::infinity();
  lateral_ = options.lateral_spacings * s;
  // Only surfels this near are asked: the far side of a solid more than a few spacings thick is
  // not a wall the candidate stands behind.
  search_ = std::max(front_, options.behind_spacings * s) + lateral_;
}

bool ObservedSurface::Test(const Eigen::Vector3f& p, bool behind) const {
  if (index_ == nullptr) return false;
  const float search = behind ? search_ : front_ + lateral_;
  for (uint32_t q : index_->WithinRadius(p, search)) {
    const Eigen::Vector3f& n = seen_normals_[q];
    const Eigen::Vector3f d = p - index_->points()[q];
    const float along = d.dot(n);
    if ((along > front_ || (behind && along < -behind_)) &&
        (d - along * n).squaredNorm() < lateral_ * lateral_) {
      return true;
    }
  }
  return false;
}

}  // namespace instascene::generation
