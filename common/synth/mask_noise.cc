#include "common/synth/mask_noise.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>
#include <random>
#include <set>

#include "absl/strings/str_cat.h"
#include "common/synth/mask_noise_steps.h"

namespace instascene {
namespace {
using mask_noise::FinishMasks;
using mask_noise::MergedInto;
using mask_noise::MergeTouching;
using mask_noise::RootOf;

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

// Areas, centroids and touching pairs of the ground-truth instances.
struct InstanceStats {
  std::map<uint16_t, size_t> area;
  std::map<uint16_t, std::pair<double, double>> centroid;  // pixel sums
  std::set<std::pair<uint16_t, uint16_t>> touching;
};
InstanceStats MeasureInstances(const LabelMap& gt) {
  InstanceStats s;
  const int w = gt.width, h = gt.height;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const uint16_t id = gt.labels[static_cast<size_t>(y) * w + x];
      if (id == 0) continue;
      ++s.area[id];
      s.centroid[id].first += x;
      s.centroid[id].second += y;
      const uint16_t right = x + 1 < w ? gt.labels[static_cast<size_t>(y) * w + x + 1] : 0;
      const uint16_t down = y + 1 < h ? gt.labels[static_cast<size_t>(y + 1) * w + x] : 0;
      for (uint16_t other : {right, down}) {
        if (other != 0 && other != id)
          s.touching.insert({std::min(id, other), std::max(id, other)});
      }
    }
  }
  return s;
}

// 1. Under-segmentation: touching instances merged (labels rewritten through a union-find style
// map); 2. over-segmentation: instances cut by a random line through their centroid, the far
// side a new label.
LabelMap MergeAndSplit(const LabelMap& gt, const MaskNoiseOptions& o, const InstanceStats& stats,
                       std::mt19937_64& rng, uint16_t* next_label) {
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  const int w = gt.width, h = gt.height;
  LabelMap map = gt;
  MergedInto merged_into = MergeTouching(o, rng, stats.touching);
  std::map<uint16_t, std::array<double, 4>> split_line;  // instance -> (cx, cy, nx, ny)
  for (const auto& [id, a] : stats.area) {
    if (a < 50 || uni(rng) >= o.split_probability) continue;
    const double angle = uni(rng) * 3.14159265358979;
    const auto& c = stats.centroid.at(id);
    split_line[id] = {c.first / a, c.second / a, std::cos(angle), std::sin(angle)};
  }
  std::map<uint16_t, uint16_t> split_label;
  for (auto& [id, line] : split_line) split_label[id] = (*next_label)++;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      uint16_t& label = map.labels[static_cast<size_t>(y) * w + x];
      if (label == 0) continue;
      const uint16_t original = label;
      label = RootOf(merged_into, original);
      auto it = split_line.find(original);
      if (it != split_line.end()) {
        const auto& l = it->second;
        if ((x - l[0]) * l[2] + (y - l[1]) * l[3] > 0) label = split_label[original];
      }
    }
  }
  return map;
}

// 3. Misses of small instances; 4. boundary jitter (each kept mask grown or shrunk a few pixels).
void MissAndJitter(const MaskNoiseOptions& o, std::mt19937_64& rng, LabelMap* map) {
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  const size_t n = map->labels.size();
  std::map<uint16_t, size_t> new_area;
  for (uint16_t v : map->labels)
    if (v != 0) ++new_area[v];
  std::set<uint16_t> missed;
  for (const auto& [id, a] : new_area) {
    if (a < o.miss_area_fraction * n && uni(rng) < o.miss_probability) missed.insert(id);
  }
  for (uint16_t& v : map->labels)
    if (missed.count(v)) v = 0;
  if (o.jitter_px > 0) {
    for (const auto& [id, a] : new_area) {
      if (missed.count(id)) continue;
      const int steps = std::uniform_int_distribution<int>(-o.jitter_px, o.jitter_px)(rng);
      for (int s = 0; s < std::abs(steps); ++s) MorphStep(*map, id, steps > 0);
    }
  }
}

// 5. Spurious masks: ellipses on background pixels, a Poisson number per view.
void AddSpuriousMasks(const LabelMap& gt, const MaskNoiseOptions& o, std::mt19937_64& rng,
                      uint16_t* next_label, LabelMap* map) {
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  const int w = gt.width, h = gt.height;
  std::poisson_distribution<int> spurious(o.spurious_per_view);
  const int count = o.spurious_per_view > 0 ? spurious(rng) : 0;
  for (int s = 0; s < count; ++s) {
    const double cx = uni(rng) * w, cy = uni(rng) * h;
    const double rx = (0.04 + 0.08 * uni(rng)) * w, ry = (0.04 + 0.08 * uni(rng)) * h;
    const uint16_t id = (*next_label)++;
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        uint16_t& v = map->labels[static_cast<size_t>(y) * w + x];
        const double dx = (x - cx) / rx, dy = (y - cy) / ry;
        if (v == 0 && gt.labels[static_cast<size_t>(y) * w + x] == 0 && dx * dx + dy * dy <= 1.0)
          v = id;
      }
    }
  }
}

}  // namespace

namespace mask_noise {

void FinishMasks(LabelMap& map, const MaskNoiseOptions& o, std::mt19937_64& rng) {
  const size_t n = map.labels.size();
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
}

float Uniform(std::mt19937_64& rng) {
  return std::uniform_real_distribution<float>(0.0f, 1.0f)(rng);
}

uint16_t RootOf(MergedInto& merged_into, uint16_t id) {
  while (merged_into.count(id)) id = merged_into[id];
  return id;
}

MergedInto MergeTouching(const MaskNoiseOptions& o, std::mt19937_64& rng,
                         const std::set<std::pair<uint16_t, uint16_t>>& touching) {
  MergedInto merged_into;
  for (const auto& [a, b] : touching)
    if (Uniform(rng) < o.merge_probability && RootOf(merged_into, a) != RootOf(merged_into, b))
      merged_into[RootOf(merged_into, b)] = RootOf(merged_into, a);
  return merged_into;
}

}  // namespace mask_noise

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
  } else if (level == "sam-low" || level == "sam-medium" || level == "sam-high") {
    const int k = level == "sam-low" ? 0 : level == "sam-medium" ? 1 : 2;
    o.part_family = true;
    o.part_split_probability = std::array<float, 3>{0.1f, 0.25f, 0.4f}[k];
    o.merge_probability = std::array<float, 3>{0.08f, 0.2f, 0.35f}[k];
    o.similar_merge_probability = std::array<float, 3>{0.03f, 0.08f, 0.15f}[k];
    o.miss_probability = std::array<float, 3>{0.15f, 0.3f, 0.5f}[k];
    o.miss_area_fraction = 0.006f;
    o.bleed_px = std::array<int, 3>{1, 2, 4}[k];
    o.flicker_probability = std::array<float, 3>{0.1f, 0.25f, 0.4f}[k];
  } else {
    return absl::InvalidArgumentError(absl::StrCat(
        "unknown mask noise level '", level,
        "' (none, low, medium, high; part-aware family: sam-low, sam-medium, sam-high)"));
  }
  return o;
}

LabelMap SimulateSegmenter(const LabelMap& gt, const MaskNoiseOptions& o, uint64_t seed) {
  std::mt19937_64 rng(seed);
  const InstanceStats stats = MeasureInstances(gt);
  if (o.part_family)
    return mask_noise::SimulatePartSegmenter(gt, o, rng, stats.area, stats.touching);
  uint16_t next_label =
      gt.labels.empty()
          ? 1
          : static_cast<uint16_t>(*std::max_element(gt.labels.begin(), gt.labels.end()) + 1);
  LabelMap map = MergeAndSplit(gt, o, stats, rng, &next_label);
  MissAndJitter(o, rng, &map);
  AddSpuriousMasks(gt, o, rng, &next_label, &map);
  FinishMasks(map, o, rng);
  return map;
}

}  // namespace instascene
