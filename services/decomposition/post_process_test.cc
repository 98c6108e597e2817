#include <gtest/gtest.h>

#include <numeric>
#include <tuple>

#include "services/decomposition/decompose.h"
#include "services/decomposition/instance_merging.h"
#include "services/decomposition/mask_graph.h"
#include "services/decomposition/post_process.h"
#include "services/decomposition/testing/hand_trackers.h"
#include "services/decomposition/unlabelled_gaussians.h"

namespace instascene::decomposition {
namespace {

// A (0..99) and B (100..199) are the two sides of one object, C (200..299) its neighbour. Masks
// hold A and B together in 3 frames and apart in 1 (a part split); B and C together in 2 frames
// (merged masks) and apart in 2; A and C together in 1, apart in 3. Only A and B merge.
TEST(MergeUnseparated, TwoSidesOfOneObjectMergeNeighboursDoNot) {
  const TrackerSet set = MakeSet(4, 300,
                                 {{0, 1, 0, 200},
                                  {0, 2, 200, 300},
                                  {1, 1, 0, 200},
                                  {1, 2, 200, 300},
                                  {2, 1, 0, 100},
                                  {2, 2, 100, 300},
                                  {3, 1, 0, 300}});
  std::vector<Instance> instances(3);
  for (uint32_t k = 0; k < 3; ++k) {
    for (uint32_t g = 100 * k; g < 100 * (k + 1); ++g) instances[k].gaussians.push_back(g);
    instances[k].masks.push_back(k);
    instances[k].coverage.push_back(1.0f);
  }
  DecompositionOptions options;
  options.merge_min_joins = 0;  // off
  std::vector<Instance> unchanged = instances;
  EXPECT_EQ(MergeUnseparatedInstances(set, options, &unchanged), 0);
  EXPECT_EQ(unchanged.size(), 3u);
  options.merge_min_joins = 2;
  ASSERT_EQ(MergeUnseparatedInstances(set, options, &instances), 1);
  ASSERT_EQ(instances.size(), 2u);
  EXPECT_EQ(instances[0].gaussians.size(), 200u);
  EXPECT_EQ(instances[0].gaussians.front(), 0u);
  EXPECT_EQ(instances[0].gaussians.back(), 199u);
  EXPECT_EQ(instances[0].masks, (std::vector<uint32_t>{0, 1}));
  EXPECT_EQ(instances[1].gaussians.front(), 200u);
  options.merge_max_separation = 0.2;  // A and B's 1 of 4 is now too many
  std::vector<Instance> strict(3);
  for (uint32_t k = 0; k < 3; ++k) {
    for (uint32_t g = 100 * k; g < 100 * (k + 1); ++g) strict[k].gaussians.push_back(g);
  }
  EXPECT_EQ(MergeUnseparatedInstances(set, options, &strict), 0);
}

// A (0..99) and B (100..199) are one object's front and back, seen in two arcs of views that
// never hold both: views 0-3 hold A, their mask also taking 10 of B's Gaussians at the seam;
// views 4-7 hold B, with 10 of A's. C (200..299) and D (300..399) are touching neighbours: views
// 0-3 hold D, C's 10 Gaussians there in a mask of their own; views 4-7 hold C. Only A and B merge,
// and not when one frame (8) holds them apart.
std::vector<Instance> MergedByGlimpses(int glimpse_min, bool held_apart_once) {
  std::vector<ListMask> masks;
  auto join = [](std::vector<uint32_t> a, const std::vector<uint32_t>& b) {
    a.insert(a.end(), b.begin(), b.end());
    std::sort(a.begin(), a.end());
    return a;
  };
  for (int v = 0; v < 4; ++v) {
    masks.push_back({v, 1, join(Range(0, 100), Range(100, 110))});
    masks.push_back({v, 2, Range(300, 400)});
    masks.push_back({v, 3, Range(200, 210)});
  }
  for (int v = 4; v < 8; ++v) {
    masks.push_back({v, 1, join(Range(90, 100), Range(100, 200))});
    masks.push_back({v, 2, Range(200, 300)});
  }
  if (held_apart_once) {
    masks.push_back({8, 1, Range(0, 100)});
    masks.push_back({8, 2, Range(100, 200)});
  }
  const TrackerSet set = MakeSetFromLists(9, 400, masks);
  std::vector<Instance> instances(4);
  for (uint32_t k = 0; k < 4; ++k) instances[k].gaussians = Range(100 * k, 100 * (k + 1));
  DecompositionOptions options;
  options.merge_glimpse_min = glimpse_min;
  MergeUnseparatedInstances(set, options, &instances);
  return instances;
}

TEST(MergeUnseparated, TwoArcsOfViewsThatMeetNowhereMergeByTheirGlimpses) {
  EXPECT_EQ(MergedByGlimpses(0, false).size(), 4u);  // off: no frame holds A and B together
  const std::vector<Instance> merged = MergedByGlimpses(20, false);
  ASSERT_EQ(merged.size(), 3u);
  EXPECT_EQ(merged[0].gaussians, Range(0, 200));
  EXPECT_EQ(merged[1].gaussians, Range(200, 300));
  EXPECT_EQ(merged[2].gaussians, Range(300, 400));
  EXPECT_EQ(MergedByGlimpses(100, false).size(), 4u);  // 80 glimpsed Gaussians: too few
  EXPECT_EQ(MergedByGlimpses(20, true).size(), 4u);    // held apart in frame 8
}

TEST(PostProcess, GaussiansOnlyMergedMasksHoldJoinTheNearestHeldInstance) {
  // Object A: instance 0 holds 0-59, its Gaussians 60-99 lie in no instance (only masks merging
  // it with B hold them, or whole masks of A the clustering did not keep). B: instance 1, 100-199.
  // 200-209: table beside A that one bleeding mask of A covers. 210-249: an object the
  // clustering missed, held by its own masks only.
  auto join = [](std::vector<uint32_t> a, const std::vector<uint32_t>& b) {
    a.insert(a.end(), b.begin(), b.end());
    return a;
  };
  const TrackerSet set = MakeSetFromLists(
      4, 250,
      {{0, 1, join(Range(0, 100), Range(200, 210))},  // A whole, bleeding onto the table
       {0, 2, Range(100, 200)},
       {0, 3, Range(210, 250)},
       {1, 1, Range(0, 200)},  // A and B merged
       {1, 3, Range(210, 250)},
       {2, 1, Range(0, 60)},  // a part of A, the rest unmasked
       {2, 2, Range(100, 200)},
       {3, 1, Range(0, 200)},  // merged again
       {3, 3, Range(210, 250)}});
  GaussianCloud cloud;
  cloud.Resize(250);
  for (int g = 0; g < 250; ++g) {
    float x = 0.001f * g;                              // A, its orphans, B: 1 mm apart on a line
    if (g >= 200 && g < 210) x = -0.001f * (g - 199);  // the table, before A
    if (g >= 210) x = 5.0f + 0.001f * g;               // far away
    cloud.positions[3 * g] = x;
  }
  // Runs the step on fresh instances (A: 0-59, B: 100-199); returns (joined, A, B).
  auto label = [&](double min_held, float step, int threads) {
    DecompositionOptions options;
    options.orphan_min_held = min_held;
    options.num_threads = threads;
    std::vector<Instance> instances(2);
    instances[0].gaussians = Range(0, 60);
    instances[1].gaussians = Range(100, 200);
    const size_t joined = LabelOrphanGaussians(set, cloud, step, options, &instances);
    return std::make_tuple(joined, instances[0].gaussians, instances[1].gaussians);
  };
  // Orphans 60-99: A held by their masks in frames 0, 1, 3 (3 of 4), B in 1 and 3 (2 of 4): both
  // qualify at 0.5, and each grows from its end of the line in 1 mm steps: they meet halfway. The
  // table: A in 1 of 4. The missed object: none.
  EXPECT_EQ(label(0.5, 0.0015f, 1),
            std::make_tuple(size_t{40}, Range(0, 80), join(Range(80, 100), Range(100, 200))));
  // Above 0.5 only A qualifies; above 0.75 none does; above 1 the step is off.
  EXPECT_EQ(label(0.7, 0.0015f, 1), std::make_tuple(size_t{40}, Range(0, 100), Range(100, 200)));
  EXPECT_EQ(label(0.8, 0.0015f, 1), std::make_tuple(size_t{0}, Range(0, 60), Range(100, 200)));
  EXPECT_EQ(label(2.0, 0.0015f, 1), std::make_tuple(size_t{0}, Range(0, 60), Range(100, 200)));
  // Steps shorter than the 1 mm spacing reach no orphan.
  EXPECT_EQ(std::get<0>(label(0.5, 0.0005f, 1)), 0u);
  // The answer does not depend on the thread count.
  EXPECT_EQ(label(0.5, 0.0015f, 2), label(0.5, 0.0015f, 1));
}

TEST(PostProcess, FramesThatMissedAnInstanceDoNotCountAgainstItsOrphans) {
  // Object C: instance 0-59, orphans 60-99 (its thin rim: traced, outside the masks of views 4
  // and 5). 100-109: table beside it, covered by one bleeding mask. Views 0 and 1 missed C
  // entirely (no mask there), views 2 and 3 mask it whole, views 4 and 5 mask its instance part.
  const TrackerSet set = MakeSetFromLists(6, 110,
                                          {{2, 1, Range(0, 100)},
                                           {3, 1, Range(0, 110)},  // bleeding onto the table
                                           {4, 1, Range(0, 60)},
                                           {5, 1, Range(0, 60)}});
  GaussianCloud cloud;
  cloud.Resize(110);
  for (int g = 0; g < 110; ++g) {
    cloud.positions[3 * g] = g < 100 ? 0.001f * g : -0.001f * (g - 99);  // the table before C
  }
  auto label = [&](bool skip_missed, int threads) {
    DecompositionOptions options;
    options.orphan_skips_missed_frames = skip_missed;
    options.num_threads = threads;
    std::vector<Instance> instances(1);
    instances[0].gaussians = Range(0, 60);
    LabelOrphanGaussians(set, cloud, 0.0015f, options, &instances);
    return instances[0].gaussians;
  };
  // Every traced frame counted: the rim is held in 2 of 6 frames, too few. Without the two frames
  // that missed C: 2 of 4. The table: 1 of 6, then 1 of 4, out either way.
  EXPECT_EQ(label(false, 1), Range(0, 60));
  EXPECT_EQ(label(true, 1), Range(0, 100));
  EXPECT_EQ(label(true, 2), label(true, 1));
}

TEST(PostProcess, UntracedGaussiansJoinTheInstanceOfTheNearestTracedOne) {
  // Gaussians 0-4 traced and in the instance (x = 0 .. 0.4), 5-9 traced and in none (x = 2 ..
  // 2.4); 10-14 untraced: 10-12 beside the instance, 13 beside the unclaimed ones, 14 beyond the
  // radius from everything.
  TrackerSet set = MakeSet(1, 15, {{0, 1, 0, 5}});
  set.frames.clear();
  set.frame_offsets.assign(1, 0);
  for (uint32_t g = 0; g < 15; ++g) {
    if (g < 10) set.frames.push_back(0);
    set.frame_offsets.push_back(set.frames.size());
  }
  GaussianCloud cloud;
  cloud.Resize(15);
  const float x[15] = {0,    0.1f, 0.2f,  0.3f,  0.4f,  2,     2.1f, 2.2f,
                       2.3f, 2.4f, 0.05f, 0.15f, 0.42f, 2.05f, 5};
  for (int g = 0; g < 15; ++g) cloud.positions[3 * g] = x[g];
  std::vector<Instance> instances(1);
  instances[0].gaussians = {0, 1, 2, 3, 4};
  EXPECT_EQ(LabelUntracedGaussians(set, cloud, 0.5f, 1, &instances), 3u);
  EXPECT_EQ(instances[0].gaussians, (std::vector<uint32_t>{0, 1, 2, 3, 4, 10, 11, 12}));
  // Radius 0 is off.
  instances[0].gaussians = {0, 1, 2, 3, 4};
  EXPECT_EQ(LabelUntracedGaussians(set, cloud, 0.0f, 1, &instances), 0u);
  EXPECT_EQ(instances[0].gaussians.size(), 5u);
}

}  // namespace
}  // namespace instascene::decomposition
