#include "services/generation/object_frame.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "common/geometry/point_index.h"
#include "common/geometry/rigid.h"

namespace instascene::generation {
namespace {

Eigen::Vector3f MeanUp(const std::vector<PinholeCamera>& cameras) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  // OpenCV axes: the camera's y points down, so its up in the world is -row 1 of R.
  for (const PinholeCamera& c : cameras) sum -= c.camera_from_world.rotation.row(1).transpose();
  if (sum.norm() < 1e-9) return Eigen::Vector3f::UnitZ();
  return sum.normalized().cast<float>();
}

float Median(std::vector<float> values) {
  if (values.empty()) return 0;
  const auto mid = values.begin() + values.size() / 2;
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

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

ObjectFrame ComputeObjectFrame(const GaussianCloud& cloud, const InstanceSplit& split,
                               const std::vector<PinholeCamera>& cameras) {
  ObjectFrame frame;
  // Up: the cameras' mean up is only rough (a capture that looks down tilts it towards the
  // scene's back), so it is refined by the normals of the support surfaces around the object.
  frame.up = MeanUp(cameras);
  std::vector<Eigen::Vector3f> points;
  points.reserve(split.instance.size());
  Eigen::AlignedBox3f box;
  for (uint32_t g : split.instance) {
    points.emplace_back(&cloud.positions[3 * g]);
    box.extend(points.back());
  }
  frame.center = box.center();
  frame.bottom_height = std::numeric_limits<float>::infinity();
  for (const Eigen::Vector3f& p : points) {
    frame.radius = std::max(frame.radius, (p - frame.center).norm());
    frame.bottom_height = std::min(frame.bottom_height, frame.up.dot(p));
  }
  frame.spacing = MedianSpacing(points);
  auto normal_of = [&](uint32_t g) {
    const float* q = &cloud.rotations[4 * g];
    return Eigen::Vector3f(RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]).col(2).cast<float>());
  };
  auto in_footprint = [&](const Eigen::Vector3f& p, float reach) {
    const Eigen::Vector3f offset = p - frame.center;
    return (offset - offset.dot(frame.up) * frame.up).norm() <= reach;
  };
  // 1. Up: the mode of the normals of occluder surfels near and below the object that face
  // roughly up (within 35 degrees of the camera estimate): the support's orientation, robust
  // against neighbouring objects' tilted surfaces.
  std::vector<Eigen::Vector3f> candidates;
  for (uint32_t g : split.occluders) {
    const Eigen::Vector3f p(&cloud.positions[3 * g]);
    const float h = frame.up.dot(p);
    if (h > frame.bottom_height + 0.1f * frame.radius || h < frame.bottom_height - frame.radius ||
        !in_footprint(p, 2.0f * frame.radius)) {
      continue;
    }
    Eigen::Vector3f n = normal_of(g);
    if (n.dot(frame.up) < 0) n = -n;
    if (n.dot(frame.up) >= 0.82f) candidates.push_back(n);
  }
  if (candidates.size() >= 20) {
    constexpr float kModeCos = 0.985f;  // 10 degrees
    const size_t stride = std::max<size_t>(1, candidates.size() / 400);
    size_t best = 0, best_count = 0;
    for (size_t i = 0; i < candidates.size(); i += stride) {
      size_t count = 0;
      for (const Eigen::Vector3f& n : candidates) count += n.dot(candidates[i]) >= kModeCos;
      if (count > best_count) {
        best = i;
        best_count = count;
      }
    }
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3f& n : candidates) {
      if (n.dot(candidates[best]) >= kModeCos) sum += n.cast<double>();
    }
    frame.up = sum.normalized().cast<float>();
    frame.bottom_height = std::numeric_limits<float>::infinity();
    for (const Eigen::Vector3f& p : points) {
      frame.bottom_height = std::min(frame.bottom_height, frame.up.dot(p));
    }
  }
  // 2. Support: occluder surfels that face up, within two radii (what lies right under the
  // object is rarely reconstructed), at most a quarter radius below the bottom.
  std::vector<float> heights;
  const float below = 0.25f * frame.radius, above = 0.05f * frame.radius;
  for (uint32_t g : split.occluders) {
    const Eigen::Vector3f p(&cloud.positions[3 * g]);
    const float h = frame.up.dot(p);
    if (h < frame.bottom_height - below || h > frame.bottom_height + above) continue;
    if (!in_footprint(p, 2.0f * frame.radius)) continue;
    if (std::abs(normal_of(g).dot(frame.up)) < 0.9f) continue;
    heights.push_back(h);
  }
  if (heights.size() >= 20) {
    frame.has_support = true;
    frame.support_height = Median(std::move(heights));
  }
  return frame;
}

}  // namespace instascene::generation
