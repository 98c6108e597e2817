#include "services/generation/object_frame.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <optional>

#include "absl/strings/str_cat.h"
#include "common/geometry/point_index.h"
#include "services/generation/frame_support.h"

namespace instascene::generation {
namespace {

float MedianSpacing(const std::vector<Eigen::Vector3f>& points) {
  if (points.size() < 2) return 0;
  const PointIndex3 index(points);
  std::vector<float> nearest;
  const size_t stride = std::max<size_t>(1, points.size() / 4000);
  for (size_t i = 0; i < points.size(); i += stride) {
    const auto knn = index.KNearest(points[i], 2);
    nearest.push_back(std::sqrt(knn.back().second));
  }
  return Median(std::move(nearest));
}

// Per point, its connected component (points linked within `link`, repeatedly); `sizes` gets
// each component's size.
std::vector<int> LinkedComponents(const std::vector<Eigen::Vector3f>& points, float link,
                                  std::vector<size_t>* sizes) {
  const PointIndex3 index(points);
  std::vector<int> component(points.size(), -1);
  std::vector<uint32_t> stack;
  for (uint32_t seed = 0; seed < points.size(); ++seed) {
    if (component[seed] >= 0) continue;
    const int c = static_cast<int>(sizes->size());
    sizes->push_back(0);
    component[seed] = c;
    stack.push_back(seed);
    while (!stack.empty()) {
      const uint32_t i = stack.back();
      stack.pop_back();
      ++(*sizes)[c];
      for (uint32_t j : index.WithinRadius(points[i], link)) {
        if (component[j] < 0) {
          component[j] = c;
          stack.push_back(j);
        }
      }
    }
  }
  return component;
}

}  // namespace

Eigen::Matrix3f ObjectFrame::Basis() const {
  const Eigen::Vector3f helper =
      std::abs(up.x()) < 0.9f ? Eigen::Vector3f::UnitX() : Eigen::Vector3f::UnitY();
  const Eigen::Vector3f x = (helper - helper.dot(up) * up).normalized();
  Eigen::Matrix3f basis;
  basis << x, up.cross(x), up;
  return basis;
}

absl::StatusOr<InstanceSplit> SplitInstance(const std::vector<uint32_t>& labels, uint32_t id,
                                            size_t min_gaussians) {
  InstanceSplit split;
  for (uint32_t g = 0; g < labels.size(); ++g) {
    (labels[g] == id ? split.instance : split.occluders).push_back(g);
  }
  if (split.instance.size() < min_gaussians) {
    return absl::FailedPreconditionError(absl::StrCat(
        "instance ", id, " has ", split.instance.size(), " Gaussians; completion needs at least ",
        min_gaussians, split.instance.empty() ? " (empty instance)" : " (degenerate object)"));
  }
  return split;
}

StrayComponents RemoveStrayGaussians(const GaussianCloud& cloud, InstanceSplit* split,
                                     float link_spacings, float min_share) {
  std::vector<Eigen::Vector3f> points;
  points.reserve(split->instance.size());
  for (uint32_t g : split->instance) points.emplace_back(&cloud.positions[3 * g]);
  const float link = link_spacings * MedianSpacing(points);
  if (!(link > 0)) return {};
  std::vector<size_t> sizes;
  const std::vector<int> component = LinkedComponents(points, link, &sizes);
  const size_t largest = *std::max_element(sizes.begin(), sizes.end());
  std::vector<uint32_t> kept;
  std::vector<int> stray_of(sizes.size(), -1);
  StrayComponents strays;
  for (size_t i = 0; i < points.size(); ++i) {
    const int c = component[i];
    if (sizes[c] >= min_share * largest) {
      kept.push_back(split->instance[i]);
      continue;
    }
    if (stray_of[c] < 0) {
      stray_of[c] = static_cast<int>(strays.size());
      strays.emplace_back();
    }
    strays[stray_of[c]].push_back(split->instance[i]);
    split->occluders.push_back(split->instance[i]);
  }
  split->outliers += split->instance.size() - kept.size();
  split->instance = std::move(kept);
  std::sort(split->occluders.begin(), split->occluders.end());
  return strays;
}

size_t ReturnTips(const GaussianCloud& cloud, const ObjectFrame& frame,
                  const StrayComponents& strays, InstanceSplit* split, size_t max_surfels,
                  float max_gap_spacings) {
  if (strays.empty() || split->instance.empty() || !(frame.spacing > 0)) return 0;
  auto position = [&](uint32_t g) { return Eigen::Vector3f(&cloud.positions[3 * g]); };
  const Eigen::Vector3f up = frame.up;
  auto horizontal = [&](const Eigen::Vector3f& p) { return Eigen::Vector3f(p - up.dot(p) * up); };
  float top = -std::numeric_limits<float>::infinity();
  for (uint32_t g : split->instance) top = std::max(top, up.dot(position(g)));
  // The top band's centre and farthest reach from it, across the up.
  Eigen::Vector3f centre = Eigen::Vector3f::Zero();
  std::vector<Eigen::Vector3f> band;
  for (uint32_t g : split->instance) {
    if (up.dot(position(g)) < top - frame.spacing) continue;
    band.push_back(horizontal(position(g)));
    centre += band.back();
  }
  centre /= static_cast<float>(band.size());
  float reach = 0;
  for (const Eigen::Vector3f& p : band) reach = std::max(reach, (p - centre).norm());
  reach += frame.spacing;
  std::vector<uint32_t> returned;
  for (const std::vector<uint32_t>& component : strays) {
    if (component.empty() || component.size() > max_surfels) continue;
    float lowest = std::numeric_limits<float>::infinity();
    bool over_top = true;
    for (uint32_t g : component) {
      const Eigen::Vector3f p = position(g);
      lowest = std::min(lowest, up.dot(p));
      over_top = over_top && (horizontal(p) - centre).norm() <= reach;
    }
    if (over_top && lowest > top && lowest - top <= max_gap_spacings * frame.spacing) {
      returned.insert(returned.end(), component.begin(), component.end());
    }
  }
  if (returned.empty()) return 0;
  std::sort(returned.begin(), returned.end());
  std::vector<uint32_t> occluders;
  std::set_difference(split->occluders.begin(), split->occluders.end(), returned.begin(),
                      returned.end(), std::back_inserter(occluders));
  split->occluders = std::move(occluders);
  split->instance.insert(split->instance.end(), returned.begin(), returned.end());
  std::sort(split->instance.begin(), split->instance.end());
  split->outliers -= returned.size();
  return returned.size();
}

std::vector<uint8_t> NeighbourLabelled(const GaussianCloud& cloud,
                                       const std::vector<uint32_t>& labels,
                                       const InstanceSplit& split, const ObjectFrame& frame, int k,
                                       float reach_spacings) {
  std::vector<uint8_t> out(split.instance.size(), 0);
  const float reach = reach_spacings * frame.spacing;
  if (split.instance.empty() || !(reach > 0) || k <= 0) return out;
  auto position = [&](uint32_t g) { return Eigen::Vector3f(&cloud.positions[3 * g]); };
  // Only the occluders that can be near the instance, and not the instance's own surfels that
  // left it (strays, the support's surfels): they still carry its label.
  const uint32_t own = split.instance[0] < labels.size() ? labels[split.instance[0]] : 0;
  const float near = frame.radius + reach;
  std::vector<Eigen::Vector3f> points;
  std::vector<uint32_t> owners;
  for (uint32_t g : split.occluders) {
    if ((position(g) - frame.center).squaredNorm() > near * near) continue;
    points.push_back(position(g));
    owners.push_back(g < labels.size() ? labels[g] : 0);
  }
  if (points.empty()) return out;
  const PointIndex3 index(std::move(points));
  std::vector<uint32_t> seen;
  for (size_t i = 0; i < split.instance.size(); ++i) {
    seen.clear();
    for (const auto& [j, d2] : index.KNearest(position(split.instance[i]), k)) {
      if (d2 <= reach * reach && owners[j] != 0 && owners[j] != own) seen.push_back(owners[j]);
    }
    std::sort(seen.begin(), seen.end());
    for (size_t a = 0; a < seen.size();) {
      size_t b = a;
      while (b < seen.size() && seen[b] == seen[a]) ++b;
      if (2 * (b - a) >= static_cast<size_t>(k)) out[i] = 1;
      a = b;
    }
  }
  return out;
}

size_t RemoveSupportSurfels(const GaussianCloud& cloud, const ObjectFrame& frame,
                            InstanceSplit* split, float band_spacings) {
  if (!frame.has_support || !(frame.spacing > 0) || cloud.num_scales != 2) return 0;
  const float band = band_spacings * frame.spacing;
  const float min_cos = std::cos(15.0f * static_cast<float>(M_PI) / 180.0f);
  std::vector<uint32_t> kept, moved;
  for (uint32_t g : split->instance) {
    const Eigen::Vector3f p(&cloud.positions[3 * g]);
    const Eigen::Vector3f normal = SurfelNormal(cloud, g);
    const bool in_support = std::abs(frame.up.dot(p) - frame.support_height) <= band &&
                            std::abs(normal.dot(frame.up)) >= min_cos;
    (in_support ? moved : kept).push_back(g);
  }
  // Nothing to move, or nothing would be left (a flat object lying on the support).
  if (moved.empty() || kept.empty()) return 0;
  split->occluders.insert(split->occluders.end(), moved.begin(), moved.end());
  std::sort(split->occluders.begin(), split->occluders.end());
  split->outliers += moved.size();
  split->instance = std::move(kept);
  return moved.size();
}

ObjectFrame ComputeObjectFrame(const GaussianCloud& cloud, const InstanceSplit& split,
                               const std::vector<PinholeCamera>& cameras) {
  ObjectFrame frame;
  std::vector<Eigen::Vector3f> points;
  points.reserve(split.instance.size());
  Eigen::AlignedBox3f box;
  for (uint32_t g : split.instance) {
    points.emplace_back(&cloud.positions[3 * g]);
    box.extend(points.back());
  }
  frame.center = box.center();
  for (const Eigen::Vector3f& p : points) {
    frame.radius = std::max(frame.radius, (p - frame.center).norm());
  }
  frame.spacing = MedianSpacing(points);
  // 1. Up: the cameras' mean up is only rough, so it is refined by the normals of the support
  // surfaces around the object.
  float horizontal_radius = 0;
  frame.up = EstimateUp(cloud, split.occluders, points, frame.center, frame.radius,
                        MeanCameraUp(cameras), &horizontal_radius);
  frame.bottom_height = std::numeric_limits<float>::infinity();
  for (const Eigen::Vector3f& p : points) {
    frame.bottom_height = std::min(frame.bottom_height, frame.up.dot(p));
  }
  // 2. Support.
  if (const std::optional<float> support =
          SupportHeight(cloud, split.occluders, frame, horizontal_radius)) {
    frame.has_support = true;
    frame.support_height = *support;
  }
  return frame;
}

}  // namespace instascene::generation
