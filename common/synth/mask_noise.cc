#include "common/synth/mask_noise.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>
#include <random>
#include <set>

#include "absl/strings/str_cat.h"

namespace instascene {
namespace {

// One 4-neighbour dilation (grow) or erosion (shrink) step of label `id` in `map`; pixels an
// erosion frees become 0, a dilation only claims pixels that are 0.
void MorphStep(LabelMap& map, uint16_t id, bool grow) {
  const int w = map.width, h = map.height;
  std::vector<uint16_t> next = map.labels;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t p = static_cast<size_t>(y) * w + x;
      bool touches = false, all_inside = true;
      const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
      for (int k = 0; k < 4; ++k) {
        if (nx[k] < 0 || ny[k] < 0 || nx[k] >= w || ny[k] >= h) continue;
        const bool in = map.labels[static_cast<size_t>(ny[k]) * w + nx[k]] == id;
        touches |= in;
        all_inside &= in;
      }
      if (grow && map.labels[p] == 0 && touches) next[p] = id;
      if (!grow && map.labels[p] == id && !all_inside) next[p] = 0;
    }
  }
  map.labels.swap(next);
}

}  // namespace

absl::StatusOr<MaskNoiseOptions> MaskNoiseOptions::Level(const std::string& level) {
  MaskNoiseOptions o;
  if (level == "none") return o;
  if (level == "low") {
    o.merge_probability = 0.05f;
    o.split_probability = 0.03f;
    o.miss_probability = 0.1f;
    o.jitter_px = 1;
    o.spurious_per_view = 0.1f;
  } else if (level == "medium") {
    o.merge_probability = 0.15f;
    o.split_probability = 0.08f;
    o.miss_probability = 0.25f;
    o.jitter_px = 2;
    o.spurious_per_view = 0.4f;
  } else if (level == "high") {
    o.merge_probability = 0.3f;
    o.split_probability = 0.15f;
    o.miss_probability = 0.45f;
    o.jitter_px = 3;
    o.spurious_per_view = 1.0f;
  } else {
    return absl::InvalidArgumentError(
        absl::StrCat("unknown mask noise level '", level, "' (none, low, medium, high)"));
  }
  return o;
}

LabelMap SimulateSegmenter(const LabelMap& gt, const MaskNoiseOptions& o, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  const int w = gt.width, h = gt.height;
  const size_t n = gt.labels.size();
  LabelMap map = gt;
  // Areas, centroids and touching pairs of the ground-truth instances.
  std::map<uint16_t, size_t> area;
  std::map<uint16_t, std::pair<double, double>> centroid;
  std::set<std::pair<uint16_t, uint16_t>> touching;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const uint16_t id = gt.labels[static_cast<size_t>(y) * w + x];
      if (id == 0) continue;
      ++area[id];
      centroid[id].first += x;
      centroid[id].second += y;
      const uint16_t right = x + 1 < w ? gt.labels[static_cast<size_t>(y) * w + x + 1] : 0;
      const uint16_t down = y + 1 < h ? gt.labels[static_cast<size_t>(y + 1) * w + x] : 0;
      for (uint16_t other : {right, down}) {
        if (other != 0 && other != id) touching.insert({std::min(id, other), std::max(id, other)});
      }
    }
  }
  // Labels are rewritten through a union-find style map (merges), then splits add new labels.
  std::map<uint16_t, uint16_t> merged_into;
  auto root = [&](uint16_t id) {
    while (merged_into.count(id)) id = merged_into[id];
    return id;
  };
  for (const auto& [a, b] : touching) {  // 1. under-segmentation
    if (uni(rng) < o.merge_probability && root(a) != root(b)) merged_into[root(b)] = root(a);
  }
  uint16_t next_label =
      gt.labels.empty()
          ? 1
          : static_cast<uint16_t>(*std::max_element(gt.labels.begin(), gt.labels.end()) + 1);
  std::map<uint16_t, std::array<double, 4>>
      split_line;                     // instance -> (cx, cy, nx, ny), new label in [3]
  for (const auto& [id, a] : area) {  // 2. over-segmentation
    if (a < 50 || uni(rng) >= o.split_probability) continue;
    const double angle = uni(rng) * 3.14159265358979;
    split_line[id] = {centroid[id].first / a, centroid[id].second / a, std::cos(angle),
                      std::sin(angle)};
  }
  std::map<uint16_t, uint16_t> split_label;
  for (auto& [id, line] : split_line) split_label[id] = next_label++;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      uint16_t& label = map.labels[static_cast<size_t>(y) * w + x];
      if (label == 0) continue;
      const uint16_t original = label;
      label = root(original);
      auto it = split_line.find(original);
      if (it != split_line.end()) {
        const auto& l = it->second;
        if ((x - l[0]) * l[2] + (y - l[1]) * l[3] > 0) label = split_label[original];
      }
    }
  }
  // 3. misses of small instances.
  std::map<uint16_t, size_t> new_area;
  for (uint16_t v : map.labels)
    if (v != 0) ++new_area[v];
  std::set<uint16_t> missed;
  for (const auto& [id, a] : new_area) {
    if (a < o.miss_area_fraction * n && uni(rng) < o.miss_probability) missed.insert(id);
  }
  for (uint16_t& v : map.labels)
    if (missed.count(v)) v = 0;
  // 4. boundary jitter.
  if (o.jitter_px > 0) {
    for (const auto& [id, a] : new_area) {
      if (missed.count(id)) continue;
      const int steps = std::uniform_int_distribution<int>(-o.jitter_px, o.jitter_px)(rng);
      for (int s = 0; s < std::abs(steps); ++s) MorphStep(map, id, steps > 0);
    }
  }
  // 5. spurious masks on background pixels.
  std::poisson_distribution<int> spurious(o.spurious_per_view);
  const int count = o.spurious_per_view > 0 ? spurious(rng) : 0;
  for (int s = 0; s < count; ++s) {
    const double cx = uni(rng) * w, cy = uni(rng) * h;
    const double rx = (0.04 + 0.08 * uni(rng)) * w, ry = (0.04 + 0.08 * uni(rng)) * h;
    const uint16_t id = next_label++;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        uint16_t& v = map.labels[static_cast<size_t>(y) * w + x];
        const double dx = (x - cx) / rx, dy = (y - cy) / ry;
        if (v == 0 && gt.labels[static_cast<size_t>(y) * w + x] == 0 && dx * dx + dy * dy <= 1.0)
          v = id;
      }
    }
  }
  // 6. minimum area, then random ids 1..K.
  std::map<uint16_t, size_t> final_area;
  for (uint16_t v : map.labels)
    if (v != 0) ++final_area[v];
  std::vector<uint16_t> kept;
  for (const auto& [id, a] : final_area)
    if (a >= o.min_area_fraction * n && a >= 1) kept.push_back(id);
  std::vector<uint16_t> ids(kept.size());
  std::iota(ids.begin(), ids.end(), uint16_t{1});
  std::shuffle(ids.begin(), ids.end(), rng);
  std::map<uint16_t, uint16_t> relabel;
  for (size_t i = 0; i < kept.size(); ++i) relabel[kept[i]] = ids[i];
  for (uint16_t& v : map.labels) {
    auto it = relabel.find(v);
    v = it == relabel.end() ? 0 : it->second;
  }
  return map;
}

}  // namespace instascene
