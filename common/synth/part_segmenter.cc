#include <algorithm>
#include <map>
#include <random>
#include <set>

#include "common/synth/mask_noise_steps.h"

namespace instascene::mask_noise {
namespace {

// b. merges: touching pairs, and similar-area pairs anywhere in the view.
MergedInto DrawMerges(const MaskNoiseOptions& o, std::mt19937_64& rng,
                      const std::map<uint16_t, size_t>& area,
                      const std::set<std::pair<uint16_t, uint16_t>>& touching) {
  MergedInto merged_into = MergeTouching(o, rng, touching);
  for (auto i = area.begin(); i != area.end(); ++i) {
    for (auto j = std::next(i); j != area.end(); ++j) {
      if (touching.count({i->first, j->first})) continue;
      const double ratio = static_cast<double>(std::min(i->second, j->second)) /
                           static_cast<double>(std::max(i->second, j->second));
      if (ratio >= 0.75 && Uniform(rng) < o.similar_merge_probability &&
          RootOf(merged_into, i->first) != RootOf(merged_into, j->first))
        merged_into[RootOf(merged_into, j->first)] = RootOf(merged_into, i->first);
    }
  }
  return merged_into;
}

// a. part splits along the instance's longer image axis, cut at random quantiles.
struct Parts {
  bool vertical;                 // cut along y (tall instance) or x
  std::vector<double> cuts;      // sorted coordinates
  std::vector<uint16_t> labels;  // one per part after the first
};
std::map<uint16_t, Parts> DrawPartSplits(const LabelMap& gt, const MaskNoiseOptions& o,
                                         std::mt19937_64& rng,
                                         const std::map<uint16_t, size_t>& area) {
  uint16_t next_label =
      gt.labels.empty()
          ? 1
          : static_cast<uint16_t>(*std::max_element(gt.labels.begin(), gt.labels.end()) + 1);
  std::map<uint16_t, std::vector<int>> xs, ys;
  for (int y = 0; y < gt.height; ++y)
    for (int x = 0; x < gt.width; ++x)
      if (const uint16_t id = gt.labels[static_cast<size_t>(y) * gt.width + x]; id != 0) {
        xs[id].push_back(x);
        ys[id].push_back(y);
      }
  std::map<uint16_t, Parts> parts;
  for (const auto& [id, a] : area) {
    if (a < 60 || Uniform(rng) >= o.part_split_probability) continue;
    std::vector<int> px = xs[id], py = ys[id];
    std::sort(px.begin(), px.end());
    std::sort(py.begin(), py.end());
    Parts p;
    p.vertical = py.back() - py.front() >= px.back() - px.front();
    const std::vector<int>& axis = p.vertical ? py : px;
    const int count = Uniform(rng) < 0.6f ? 2 : 3;
    for (int c = 1; c < count; ++c) {
      const double q = (c - 0.3 + 0.6 * Uniform(rng)) / count;  // near the even cut, jittered
      p.cuts.push_back(axis[static_cast<size_t>(q * (axis.size() - 1))] + 0.5);
      p.labels.push_back(next_label++);
    }
    std::sort(p.cuts.begin(), p.cuts.end());
    parts[id] = std::move(p);
  }
  return parts;
}

void ApplyMergesAndSplits(MergedInto& merged_into, const std::map<uint16_t, Parts>& parts,
                          LabelMap& map) {
  for (int y = 0; y < map.height; ++y) {
    for (int x = 0; x < map.width; ++x) {
      uint16_t& label = map.labels[static_cast<size_t>(y) * map.width + x];
      if (label == 0) continue;
      const uint16_t original = label;
      label = RootOf(merged_into, original);
      auto it = parts.find(original);
      if (it == parts.end()) continue;
      const double v = it->second.vertical ? y : x;
      for (size_t c = it->second.cuts.size(); c-- > 0;) {
        if (v > it->second.cuts[c]) {
          label = it->second.labels[c];
          break;
        }
      }
    }
  }
}

// c. misses of small masks: the missed ids, cleared from `map`.
std::set<uint16_t> DrawMisses(const MaskNoiseOptions& o, std::mt19937_64& rng,
                              const std::map<uint16_t, size_t>& mask_area, LabelMap& map) {
  std::set<uint16_t> missed;
  for (const auto& [id, a] : mask_area)
    if (a < o.miss_area_fraction * map.labels.size() && Uniform(rng) < o.miss_probability)
      missed.insert(id);
  for (uint16_t& v : map.labels)
    if (missed.count(v)) v = 0;
  return missed;
}

// d. boundary bleed into touching masks: each step, pixels of another mask next to this one
//    switch to it.
void Bleed(const MaskNoiseOptions& o, std::mt19937_64& rng,
           const std::map<uint16_t, size_t>& mask_area, const std::set<uint16_t>& missed,
           LabelMap& map) {
  const int w = map.width, h = map.height;
  for (const auto& [id, a] : mask_area) {
    if (missed.count(id) || Uniform(rng) >= 0.5f) continue;
    const int steps = std::uniform_int_distribution<int>(1, o.bleed_px)(rng);
    for (int s = 0; s < steps; ++s) {
      std::vector<uint16_t> next = map.labels;
      for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
          const size_t p = static_cast<size_t>(y) * w + x;
          if (map.labels[p] == 0 || map.labels[p] == id) continue;
          const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
          for (int k = 0; k < 4; ++k) {
            if (nx[k] < 0 || ny[k] < 0 || nx[k] >= w || ny[k] >= h) continue;
            if (map.labels[static_cast<size_t>(ny[k]) * w + nx[k]] == id) next[p] = id;
          }
        }
      }
      map.labels.swap(next);
    }
  }
}

// e. flicker: 1-3 holes of radius 1-3 px inside a mask.
void Flicker(const MaskNoiseOptions& o, std::mt19937_64& rng,
             const std::map<uint16_t, size_t>& mask_area, const std::set<uint16_t>& missed,
             LabelMap& map) {
  const int w = map.width, h = map.height;
  for (const auto& [id, a] : mask_area) {
    if (missed.count(id) || Uniform(rng) >= o.flicker_probability) continue;
    std::vector<size_t> pixels;
    for (size_t p = 0; p < map.labels.size(); ++p)
      if (map.labels[p] == id) pixels.push_back(p);
    if (pixels.empty()) continue;
    const int holes = std::uniform_int_distribution<int>(1, 3)(rng);
    for (int k = 0; k < holes; ++k) {
      const size_t c = pixels[std::uniform_int_distribution<size_t>(0, pixels.size() - 1)(rng)];
      const int cx = static_cast<int>(c % w), cy = static_cast<int>(c / w);
      const int r = std::uniform_int_distribution<int>(1, 3)(rng);
      for (int y = std::max(0, cy - r); y <= std::min(h - 1, cy + r); ++y)
        for (int x = std::max(0, cx - r); x <= std::min(w - 1, cx + r); ++x)
          if ((x - cx) * (x - cx) + (y - cy) * (y - cy) <= r * r &&
              map.labels[static_cast<size_t>(y) * w + x] == id)
            map.labels[static_cast<size_t>(y) * w + x] = 0;
    }
  }
}

}  // namespace

LabelMap SimulatePartSegmenter(const LabelMap& gt, const MaskNoiseOptions& o, std::mt19937_64& rng,
                               const std::map<uint16_t, size_t>& area,
                               const std::set<std::pair<uint16_t, uint16_t>>& touching) {
  LabelMap map = gt;
  MergedInto merged_into = DrawMerges(o, rng, area, touching);
  const std::map<uint16_t, Parts> parts = DrawPartSplits(gt, o, rng, area);
  ApplyMergesAndSplits(merged_into, parts, map);
  std::map<uint16_t, size_t> mask_area;
  for (uint16_t v : map.labels)
    if (v != 0) ++mask_area[v];
  const std::set<uint16_t> missed = DrawMisses(o, rng, mask_area, map);
  if (o.bleed_px > 0) Bleed(o, rng, mask_area, missed, map);
  Flicker(o, rng, mask_area, missed, map);
  FinishMasks(map, o, rng);
  return map;
}

}  // namespace instascene::mask_noise
