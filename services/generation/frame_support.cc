#include "services/generation/frame_support.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <numbers>

#include "common/geometry/rigid.h"

namespace instascene::generation {
namespace {

// The mean of the directions within 3 degrees of the most supported one (the mode, searched over
// at most 400 of them); nullopt for fewer than `min_count` directions. (10 degrees mixed a table's
// normals with a neighbour's top slanted 7 degrees: RESULTS.md "Object frames: the object's own
// footprint".)
std::optional<Eigen::Vector3f> ModeDirection(const std::vector<Eigen::Vector3f>& directions,
                                             size_t min_count) {
  if (directions.size() < min_count) return std::nullopt;
  constexpr float kModeCos = 0.99863f;  // 3 degrees
  const size_t stride = std::max<size_t>(1, directions.size() / 400);
  size_t best = 0, best_count = 0;
  for (size_t i = 0; i < directions.size(); i += stride) {
    size_t count = 0;
    for (const Eigen::Vector3f& n : directions) count += n.dot(directions[i]) >= kModeCos;
    if (count > best_count) {
      best = i;
      best_count = count;
    }
  }
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3f& n : directions) {
    if (n.dot(directions[best]) >= kModeCos) sum += n.cast<double>();
  }
  return sum.normalized().cast<float>();
}

float HorizontalDistance(const Eigen::Vector3f& p, const Eigen::Vector3f& center,
                         const Eigen::Vector3f& up) {
  const Eigen::Vector3f offset = p - center;
  return (offset - offset.dot(up) * up).norm();
}

// Appends g's normal, flipped to `reference`'s side, when within acos(min_cos) of it.
void AddFacing(const GaussianCloud& cloud, uint32_t g, const Eigen::Vector3f& reference,
               float min_cos, std::vector<Eigen::Vector3f>* out) {
  Eigen::Vector3f n = SurfelNormal(cloud, g);
  if (n.dot(reference) < 0) n = -n;
  if (n.dot(reference) >= min_cos) out->push_back(n);
}

float LowestHeight(const std::vector<Eigen::Vector3f>& points, const Eigen::Vector3f& up) {
  float bottom = std::numeric_limits<float>::infinity();
  for (const Eigen::Vector3f& p : points) bottom = std::min(bottom, up.dot(p));
  return bottom;
}

struct SupportCandidate {
  float height;
  int sector;    // of 8 around the object's centre
  bool outside;  // beyond the object's horizontal radius
};

// Occluder surfels that face up, within four radii (what lies right under the object is rarely
// reconstructed), below the bottom by at most one radius (the object's lower part may be hidden).
std::vector<SupportCandidate> SupportCandidates(const GaussianCloud& cloud,
                                                const std::vector<uint32_t>& occluders,
                                                const ObjectFrame& frame, float horizontal_radius) {
  std::vector<SupportCandidate> heights;
  const float below = frame.radius, above = 0.05f * frame.radius;
  const Eigen::Matrix3f basis = frame.Basis();
  for (uint32_t g : occluders) {
    const Eigen::Vector3f p(&cloud.positions[3 * g]);
    const float h = frame.up.dot(p);
    if (h < frame.bottom_height - below || h > frame.bottom_height + above) continue;
    if (HorizontalDistance(p, frame.center, frame.up) > 4.0f * frame.radius) continue;
    if (std::abs(SurfelNormal(cloud, g).dot(frame.up)) < 0.9f) continue;
    const Eigen::Vector3f q = basis.transpose() * (p - frame.center);
    constexpr float kPi = std::numbers::pi_v<float>;
    const int sector = static_cast<int>(std::floor((std::atan2(q.y(), q.x()) + kPi) / (kPi / 4)));
    heights.push_back({h, std::clamp(sector, 0, 7),
                       HorizontalDistance(p, frame.center, frame.up) > horizontal_radius});
  }
  return heights;
}

}  // namespace

Eigen::Vector3f MeanCameraUp(const std::vector<PinholeCamera>& cameras) {
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

Eigen::Vector3f SurfelNormal(const GaussianCloud& cloud, uint32_t g) {
  const float* q = &cloud.rotations[4 * g];
  return Eigen::Vector3f(RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]).col(2).cast<float>());
}

// (With only the camera estimate's 35-degree cone, a bowl whose table was hidden under it took a
// neighbour's side, 56 degrees off, for its support; RESULTS.md "Object frames".)
Eigen::Vector3f EstimateUp(const GaussianCloud& cloud, const std::vector<uint32_t>& occluders,
                           const std::vector<Eigen::Vector3f>& points,
                           const Eigen::Vector3f& center, float radius,
                           const Eigen::Vector3f& rough_up, float* horizontal_radius) {
  std::vector<Eigen::Vector3f> scene_normals;
  const size_t scene_stride = std::max<size_t>(1, occluders.size() / 20000);
  for (size_t k = 0; k < occluders.size(); k += scene_stride) {
    AddFacing(cloud, occluders[k], rough_up, 0.82f, &scene_normals);
  }
  const Eigen::Vector3f scene_up = ModeDirection(scene_normals, 20).value_or(rough_up);
  // Around the object's own footprint (twice its horizontal radius, not its radius: a tall
  // bottle's radius is its half-height, and 2 radii reached a neighbour's slanted top 15 cm away),
  // below its bottom, both about the scene's up (the cameras' is rough).
  const float bottom = LowestHeight(points, scene_up);
  *horizontal_radius = 0;
  for (const Eigen::Vector3f& p : points) {
    *horizontal_radius = std::max(*horizontal_radius, HorizontalDistance(p, center, scene_up));
  }
  const float footprint_reach = 2.0f * *horizontal_radius;
  std::vector<Eigen::Vector3f> candidates;
  for (uint32_t g : occluders) {
    const Eigen::Vector3f p(&cloud.positions[3 * g]);
    const float h = scene_up.dot(p);
    if (h > bottom + 0.1f * radius || h < bottom - radius ||
        HorizontalDistance(p, center, scene_up) > footprint_reach) {
      continue;
    }
    AddFacing(cloud, g, scene_up, 0.966f, &candidates);
  }
  return ModeDirection(candidates, 20).value_or(scene_up);
}

// Counts per one-bin window starting at each height (descending); the highest window holding at
// least a quarter of the fullest one's count (and 10) wins: the plane right under the object, not
// the underside of the table top some rays leak through to. And a plane the object stands on
// surrounds it: the window's surfels lie in at least half of the 8 sectors around it (a
// neighbouring bowl's inner floor, a few millimetres above the table and dense beside a mug, lies
// to one side; RESULTS.md "Object frames: the support surrounds the object"), outside the
// object's own footprint (a mug's inner floor, which the segmentation left out, surrounds its
// centre 5 mm above the table; RESULTS.md "Object frames: not the object's own floor"). Without
// such a window, the highest by count alone.
std::optional<float> SupportHeight(const GaussianCloud& cloud,
                                   const std::vector<uint32_t>& occluders, const ObjectFrame& frame,
                                   float horizontal_radius) {
  std::vector<SupportCandidate> heights =
      SupportCandidates(cloud, occluders, frame, horizontal_radius);
  const float bin = std::max(2.0f * frame.spacing, 0.02f * frame.radius);
  std::sort(
      heights.begin(), heights.end(),
      [](const SupportCandidate& a, const SupportCandidate& b) { return a.height > b.height; });
  std::vector<size_t> window_end(heights.size());
  size_t fullest = 0;
  for (size_t i = 0, j = 0; i < heights.size(); ++i) {
    j = std::max(j, i);
    while (j < heights.size() && heights[j].height >= heights[i].height - bin) ++j;
    window_end[i] = j;
    fullest = std::max(fullest, j - i);
  }
  auto surrounds = [&](size_t i) {
    uint8_t sectors = 0;
    for (size_t k = i; k < window_end[i]; ++k) {
      if (heights[k].outside) sectors |= uint8_t{1} << heights[k].sector;
    }
    return std::popcount(sectors) >= 4;
  };
  for (const bool need_surround : {true, false}) {
    for (size_t i = 0; i < heights.size(); ++i) {
      const size_t count = window_end[i] - i;
      if (count < 10 || 4 * count < fullest || (need_surround && !surrounds(i))) continue;
      std::vector<float> window;
      for (size_t k = i; k < window_end[i]; ++k) window.push_back(heights[k].height);
      return Median(std::move(window));
    }
  }
  return std::nullopt;
}

}  // namespace instascene::generation
