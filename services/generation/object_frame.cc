#include "services/generation/object_frame.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <numbers>
#include <optional>

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

void RemoveStrayGaussians(const GaussianCloud& cloud, InstanceSplit* split, float link_spacings,
                          float min_share) {
  std::vector<Eigen::Vector3f> points;
  points.reserve(split->instance.size());
  for (uint32_t g : split->instance) points.emplace_back(&cloud.positions[3 * g]);
  const float link = link_spacings * MedianSpacing(points);
  if (!(link > 0)) return;
  const PointIndex3 index(points);
  std::vector<int> component(points.size(), -1);
  std::vector<size_t> sizes;
  std::vector<uint32_t> stack;
  for (uint32_t seed = 0; seed < points.size(); ++seed) {
    if (component[seed] >= 0) continue;
    const int c = static_cast<int>(sizes.size());
    sizes.push_back(0);
    component[seed] = c;
    stack.push_back(seed);
    while (!stack.empty()) {
      const uint32_t i = stack.back();
      stack.pop_back();
      ++sizes[c];
      for (uint32_t j : index.WithinRadius(points[i], link)) {
        if (component[j] < 0) {
          component[j] = c;
          stack.push_back(j);
        }
      }
    }
  }
  const size_t largest = *std::max_element(sizes.begin(), sizes.end());
  std::vector<uint32_t> kept;
  for (size_t i = 0; i < points.size(); ++i) {
    if (sizes[component[i]] >= min_share * largest) {
      kept.push_back(split->instance[i]);
    } else {
      split->occluders.push_back(split->instance[i]);
    }
  }
  split->outliers += split->instance.size() - kept.size();
  split->instance = std::move(kept);
  std::sort(split->occluders.begin(), split->occluders.end());
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
    const float* q = &cloud.rotations[4 * g];
    const Eigen::Vector3f normal =
        RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]).col(2).cast<float>();
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
  // 1. Up, in two steps. (a) The scene's: the mode of the normals of every occluder surfel
  // facing roughly up (within 35 degrees of the camera estimate; at most 20000 of them, a fixed
  // stride): the support most of the scene rests on. (b) The object's: the mode of the normals
  // of occluder surfels near and below the object within 15 degrees of the scene's up: its own
  // support, robust against neighbouring objects' tilted surfaces (with only the camera
  // estimate's 35-degree cone, a bowl whose table was hidden under it took a neighbour's side,
  // 56 degrees off, for its support; RESULTS.md "Object frames").
  auto facing = [&](uint32_t g, const Eigen::Vector3f& reference, float min_cos,
                    std::vector<Eigen::Vector3f>* out) {
    Eigen::Vector3f n = normal_of(g);
    if (n.dot(reference) < 0) n = -n;
    if (n.dot(reference) >= min_cos) out->push_back(n);
  };
  std::vector<Eigen::Vector3f> scene_normals;
  const size_t scene_stride = std::max<size_t>(1, split.occluders.size() / 20000);
  for (size_t k = 0; k < split.occluders.size(); k += scene_stride) {
    facing(split.occluders[k], frame.up, 0.82f, &scene_normals);
  }
  const Eigen::Vector3f scene_up = ModeDirection(scene_normals, 20).value_or(frame.up);
  // Around the object's own footprint (twice its horizontal radius, not its radius: a tall
  // bottle's radius is its half-height, and 2 radii reached a neighbour's slanted top 15 cm away),
  // below its bottom, both about the scene's up (the cameras' is rough).
  frame.up = scene_up;
  frame.bottom_height = std::numeric_limits<float>::infinity();
  float horizontal_radius = 0;
  for (const Eigen::Vector3f& p : points) {
    const Eigen::Vector3f offset = p - frame.center;
    frame.bottom_height = std::min(frame.bottom_height, frame.up.dot(p));
    horizontal_radius =
        std::max(horizontal_radius, (offset - offset.dot(frame.up) * frame.up).norm());
  }
  const float footprint_reach = 2.0f * horizontal_radius;
  std::vector<Eigen::Vector3f> candidates;
  for (uint32_t g : split.occluders) {
    const Eigen::Vector3f p(&cloud.positions[3 * g]);
    const float h = frame.up.dot(p);
    if (h > frame.bottom_height + 0.1f * frame.radius || h < frame.bottom_height - frame.radius ||
        !in_footprint(p, footprint_reach)) {
      continue;
    }
    facing(g, scene_up, 0.966f, &candidates);
  }
  frame.up = ModeDirection(candidates, 20).value_or(scene_up);
  frame.bottom_height = std::numeric_limits<float>::infinity();
  for (const Eigen::Vector3f& p : points) {
    frame.bottom_height = std::min(frame.bottom_height, frame.up.dot(p));
  }
  // 2. Support: occluder surfels that face up, within four radii (what lies right under the
  // object is rarely reconstructed), below the bottom by at most one radius (the object's lower
  // part may be hidden).
  struct Candidate {
    float height;
    int sector;    // of 8 around the object's centre
    bool outside;  // beyond the object's horizontal radius
  };
  std::vector<Candidate> heights;
  const float below = frame.radius, above = 0.05f * frame.radius;
  const Eigen::Matrix3f basis = frame.Basis();
  for (uint32_t g : split.occluders) {
    const Eigen::Vector3f p(&cloud.positions[3 * g]);
    const float h = frame.up.dot(p);
    if (h < frame.bottom_height - below || h > frame.bottom_height + above) continue;
    if (!in_footprint(p, 4.0f * frame.radius)) continue;
    if (std::abs(normal_of(g).dot(frame.up)) < 0.9f) continue;
    const Eigen::Vector3f q = basis.transpose() * (p - frame.center);
    constexpr float kPi = std::numbers::pi_v<float>;
    const int sector = static_cast<int>(std::floor((std::atan2(q.y(), q.x()) + kPi) / (kPi / 4)));
    heights.push_back({h, std::clamp(sector, 0, 7), !in_footprint(p, horizontal_radius)});
  }
  // Counts per one-bin window starting at each height (descending); the highest window holding
  // at least a quarter of the fullest one's count (and 10) wins: the plane right under the object,
  // not the underside of the table top some rays leak through to. And a plane the object stands
  // on surrounds it: the window's surfels lie in at least half of the 8 sectors around it (a
  // neighbouring bowl's inner floor, a few millimetres above the table and dense beside a mug,
  // lies to one side; RESULTS.md "Object frames: the support surrounds the object"), outside the
  // object's own footprint (a mug's inner floor, which the segmentation left out, surrounds its
  // centre 5 mm above the table; RESULTS.md "Object frames: not the object's own floor").
  // Without such a window, the highest by count alone.
  const float bin = std::max(2.0f * frame.spacing, 0.02f * frame.radius);
  std::sort(heights.begin(), heights.end(),
            [](const Candidate& a, const Candidate& b) { return a.height > b.height; });
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
    for (size_t i = 0; i < heights.size() && !frame.has_support; ++i) {
      const size_t count = window_end[i] - i;
      if (count < 10 || 4 * count < fullest || (need_surround && !surrounds(i))) continue;
      std::vector<float> window;
      for (size_t k = i; k < window_end[i]; ++k) window.push_back(heights[k].height);
      frame.has_support = true;
      frame.support_height = Median(std::move(window));
    }
  }
  return frame;
}

}  // namespace instascene::generation
