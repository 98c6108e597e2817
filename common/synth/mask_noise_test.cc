#include "common/synth/mask_noise.h"

#include <gtest/gtest.h>

#include <map>
#include <set>

namespace instascene {
namespace {

LabelMap TwoTouchingSquares() {
  LabelMap gt{64, 48, std::vector<uint16_t>(64 * 48, 0)};
  for (int y = 10; y < 30; ++y) {
    for (int x = 10; x < 50; ++x) gt.labels[y * 64 + x] = x < 30 ? 3 : 7;
  }
  gt.labels[40 * 64 + 5] = 9;  // a 1-pixel instance: below the minimum area
  return gt;
}

TEST(MaskNoise, NoneIsGroundTruthWithRandomIds) {
  const LabelMap gt = TwoTouchingSquares();
  MaskNoiseOptions none = *MaskNoiseOptions::Level("none");
  none.min_area_fraction = 0.001f;  // 3 px on this 64x48 map
  const LabelMap noisy = SimulateSegmenter(gt, none, 5);
  std::map<uint16_t, std::set<uint16_t>> mapping;
  for (size_t p = 0; p < gt.labels.size(); ++p) {
    if (gt.labels[p] == 9) {
      EXPECT_EQ(noisy.labels[p], 0);  // dropped: below the minimum area
      continue;
    }
    mapping[gt.labels[p]].insert(noisy.labels[p]);
  }
  EXPECT_EQ(mapping[0], std::set<uint16_t>{0});
  ASSERT_EQ(mapping[3].size(), 1u);
  ASSERT_EQ(mapping[7].size(), 1u);
  EXPECT_NE(*mapping[3].begin(), *mapping[7].begin());
  EXPECT_LE(*mapping[3].begin(), 2);  // ids are 1..K
}

TEST(MaskNoise, MergesSplitsAndMissesHappenAtTheirRates) {
  const LabelMap gt = TwoTouchingSquares();
  MaskNoiseOptions merge_only;
  merge_only.merge_probability = 1.0f;
  const LabelMap merged = SimulateSegmenter(gt, merge_only, 1);
  EXPECT_EQ(merged.labels[20 * 64 + 15], merged.labels[20 * 64 + 45]);  // one mask over both
  EXPECT_NE(merged.labels[20 * 64 + 15], 0);
  MaskNoiseOptions split_only;
  split_only.split_probability = 1.0f;
  const LabelMap split = SimulateSegmenter(gt, split_only, 2);
  std::set<uint16_t> ids(split.labels.begin(), split.labels.end());
  EXPECT_EQ(ids.size(), 6u);  // background, two halves of each square, the 1-px instance
  // Over many seeds, "high" changes the mask count more often than "low".
  int changed_low = 0, changed_high = 0;
  for (uint64_t seed = 0; seed < 60; ++seed) {
    for (const char* level : {"low", "high"}) {
      const LabelMap m = SimulateSegmenter(gt, *MaskNoiseOptions::Level(level), seed);
      std::set<uint16_t> k(m.labels.begin(), m.labels.end());
      (std::string(level) == "low" ? changed_low : changed_high) += k.size() != 4;
    }
  }
  EXPECT_GT(changed_high, changed_low);
  EXPECT_FALSE(MaskNoiseOptions::Level("extreme").ok());
  // Deterministic from the seed.
  EXPECT_EQ(SimulateSegmenter(gt, *MaskNoiseOptions::Level("high"), 9).labels,
            SimulateSegmenter(gt, *MaskNoiseOptions::Level("high"), 9).labels);
}

TEST(MaskNoise, PartFamilySplitsIntoPartsMergesLookAlikesBleedsAndFlickers) {
  // A square (3) touching a wider rectangle (7), and a far square of about the size of 3 (5).
  LabelMap gt{80, 60, std::vector<uint16_t>(80 * 60, 0)};
  for (int y = 10; y < 30; ++y)
    for (int x = 10; x < 60; ++x) gt.labels[y * 80 + x] = x < 30 ? 3 : 7;
  for (int y = 40; y < 58; ++y)
    for (int x = 55; x < 77; ++x) gt.labels[y * 80 + x] = 5;
  auto count = [](const LabelMap& m) {
    std::set<uint16_t> ids(m.labels.begin(), m.labels.end());
    ids.erase(0);
    return ids.size();
  };
  MaskNoiseOptions parts;
  parts.part_family = true;
  parts.part_split_probability = 1.0f;
  const LabelMap split = SimulateSegmenter(gt, parts, 3);
  EXPECT_GE(count(split), 6u);  // every square in 2-3 parts
  // Parts are bands along the longer axis: square 3 (20 wide, 20 tall) splits along y.
  MaskNoiseOptions lookalike;
  lookalike.part_family = true;
  lookalike.similar_merge_probability = 1.0f;
  const LabelMap merged = SimulateSegmenter(gt, lookalike, 4);
  EXPECT_EQ(merged.labels[20 * 80 + 15], merged.labels[50 * 80 + 60]);  // 3 and far 5: one mask
  EXPECT_NE(merged.labels[20 * 80 + 15], merged.labels[20 * 80 + 45]);  // touching 7 is not
  MaskNoiseOptions bleed;
  bleed.part_family = true;
  bleed.bleed_px = 3;
  int moved = 0;
  for (uint64_t seed = 0; seed < 10; ++seed) {
    const LabelMap b = SimulateSegmenter(gt, bleed, seed);
    // Column 30 belongs to 7; a bleed of 3 replaces it by 3's mask in some views.
    moved += b.labels[20 * 80 + 30] == b.labels[20 * 80 + 25];
    EXPECT_EQ(b.labels[5 * 80 + 5], 0);  // background never bleeds
  }
  EXPECT_GT(moved, 0);
  MaskNoiseOptions flicker;
  flicker.part_family = true;
  flicker.flicker_probability = 1.0f;
  const LabelMap f = SimulateSegmenter(gt, flicker, 5);
  size_t holes = 0;
  for (size_t p = 0; p < gt.labels.size(); ++p) holes += gt.labels[p] != 0 && f.labels[p] == 0;
  EXPECT_GT(holes, 0u);
  // The presets exist, differ from the first family and are deterministic.
  for (const char* level : {"sam-low", "sam-medium", "sam-high"}) {
    auto o = MaskNoiseOptions::Level(level);
    ASSERT_TRUE(o.ok()) << level;
    EXPECT_TRUE(o->part_family);
    EXPECT_EQ(SimulateSegmenter(gt, *o, 9).labels, SimulateSegmenter(gt, *o, 9).labels);
  }
}

}  // namespace
}  // namespace instascene
