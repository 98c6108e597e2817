#include <gtest/gtest.h>

#include "common/core/testing/temp_dir.h"

#include <filesystem>
#include <numeric>
#include <random>
#include <tuple>

#include "common/eval/click_eval.h"
#include "common/synth/scene_writer.h"
#include "services/decomposition/decompose.h"
#include "services/decomposition/instance_merging.h"
#include "services/decomposition/mask_graph.h"
#include "services/decomposition/post_process.h"
#include "services/decomposition/unlabelled_gaussians.h"

namespace instascene::decomposition {
namespace {

// A hand-built tracker set: masks given as (view, mask id, Gaussian range [lo, hi)).
struct HandMask {
  int view;
  uint32_t id;
  uint32_t lo, hi;
};

struct ListMask {
  int view;
  uint32_t id;
  std::vector<uint32_t> gaussians;  // sorted
};

// Every Gaussian is traced in every view; it belongs to the masks that list it.
TrackerSet MakeSetFromLists(int num_views, uint32_t num_gaussians,
                            const std::vector<ListMask>& masks) {
  TrackerSet set;
  set.num_views = num_views;
  set.num_gaussians = num_gaussians;
  set.view_trackers.resize(num_views);
  std::vector<std::vector<uint32_t>> owner(num_gaussians);
  for (const ListMask& m : masks) {
    const uint32_t index = static_cast<uint32_t>(set.trackers.size());
    set.view_trackers[m.view].push_back(index);
    set.trackers.push_back(Tracker{m.view, m.id, m.gaussians});
    for (uint32_t g : m.gaussians) owner[g].push_back(index);
  }
  set.frame_offsets.push_back(0);
  set.mask_offsets.push_back(0);
  for (uint32_t g = 0; g < num_gaussians; ++g) {
    for (int v = 0; v < num_views; ++v) set.frames.push_back(static_cast<uint16_t>(v));
    set.masks.insert(set.masks.end(), owner[g].begin(), owner[g].end());
    set.frame_offsets.push_back(set.frames.size());
    set.mask_offsets.push_back(set.masks.size());
  }
  return set;
}

std::vector<uint32_t> Range(uint32_t lo, uint32_t hi) {
  std::vector<uint32_t> r(hi - lo);
  std::iota(r.begin(), r.end(), lo);
  return r;
}

TrackerSet MakeSet(int num_views, uint32_t num_gaussians, const std::vector<HandMask>& masks) {
  std::vector<ListMask> lists;
  for (const HandMask& m : masks) lists.push_back({m.view, m.id, Range(m.lo, m.hi)});
  return MakeSetFromLists(num_views, num_gaussians, lists);
}

// Gaussians on the x axis, 1 mm apart (one DBSCAN cluster); those from `far_from` on are moved
// 5 units away (a second cluster).
GaussianCloud LineCloud(int n, int far_from) {
  GaussianCloud cloud;
  cloud.Resize(n);
  for (int g = 0; g < n; ++g) {
    cloud.positions[3 * g] = 0.001f * g + (g >= far_from ? 5.0f : 0.0f);
    cloud.positions[3 * g + 1] = cloud.positions[3 * g + 2] = 0.0f;
  }
  return cloud;
}

// Steps 3-6 with the given under-segmentation flags: undo, cluster, build instances.
std::vector<Instance> InstancesWithFlags(const TrackerSet& set, const MaskJudgement& judged,
                                         const std::vector<uint8_t>& flags,
                                         const GaussianCloud& cloud,
                                         const DecompositionOptions& options) {
  MaskJudgement j = judged;
  j.undersegmented = flags;
  UndoUndersegmented(set, &j);
  return BuildInstances(set, ClusterMasks(set, j, options), cloud, options);
}

TEST(MaskGraph, TwoViewsOfOneObjectMerge) {
  const TrackerSet set = MakeSet(2, 100, {{0, 1, 0, 100}, {1, 1, 0, 100}});
  MaskJudgement j = JudgeTrackers(set, DecompositionOptions{});
  EXPECT_FALSE(j.undersegmented[0]);
  EXPECT_FALSE(j.undersegmented[1]);
  EXPECT_EQ(j.contained[0], (std::vector<uint32_t>{0, 1}));
  UndoUndersegmented(set, &j);
  const std::vector<MaskNode> nodes = ClusterMasks(set, j, DecompositionOptions{});
  ASSERT_EQ(nodes.size(), 1u);
  EXPECT_EQ(nodes[0].masks.size(), 2u);
}

// A large object masked in views 0-9 (V V^T entries of 10), a small one masked only in views 10
// and 11 (entries of 2) and a mask seen in one view only (an entry of 1). The schedule's
// percentiles stop at that 1 below the median after 10: the small object's two masks never
// cluster (and are dropped as single-mask clusters) unless the schedule ends with a floor of 2
// (DecompositionOptions::observer_floor).
TEST(MaskGraph, AnObjectSeenTogetherInTwoViewsClustersAboveTheObserverFloor) {
  std::vector<HandMask> masks;
  for (int v = 0; v < 10; ++v) masks.push_back({v, 1, 0, 100});
  masks.push_back({10, 1, 100, 140});
  masks.push_back({11, 1, 100, 140});
  masks.push_back({12, 1, 140, 180});
  const TrackerSet set = MakeSet(13, 180, masks);
  auto small_clustered = [&](double floor) {
    DecompositionOptions options;
    options.observer_floor = floor;
    MaskJudgement j = JudgeTrackers(set, options);
    UndoUndersegmented(set, &j);
    std::vector<double> schedule;
    const std::vector<MaskNode> nodes = ClusterMasks(set, j, options, &schedule);
    EXPECT_GE(schedule.size(), 1u);
    EXPECT_GT(schedule.front(), 2.0);
    for (const MaskNode& n : nodes) {
      if (n.masks == std::vector<uint32_t>{10, 11}) return true;
    }
    return false;
  };
  EXPECT_FALSE(small_clustered(0));
  EXPECT_TRUE(small_clustered(2));
}

TEST(MaskGraph, TouchingObjectsMergedInOneViewAreUndersegmentedAndStaySeparate) {
  // A = Gaussians 0..99, B = 100..199. Views 0 and 1 separate them; view 2 has one mask over both.
  const TrackerSet set = MakeSet(
      3, 200, {{0, 1, 0, 100}, {0, 2, 100, 200}, {1, 1, 0, 100}, {1, 2, 100, 200}, {2, 1, 0, 200}});
  MaskJudgement j = JudgeTrackers(set, DecompositionOptions{});
  EXPECT_TRUE(j.undersegmented[4]);
  for (int t = 0; t < 4; ++t) EXPECT_FALSE(j.undersegmented[t]) << t;
  EXPECT_TRUE(j.visible[0].Test(2));  // A is contained in the merged mask before the undo
  UndoUndersegmented(set, &j);
  EXPECT_FALSE(j.visible[0].Test(2));
  const std::vector<MaskNode> nodes = ClusterMasks(set, j, DecompositionOptions{});
  ASSERT_EQ(nodes.size(), 2u);
  EXPECT_EQ(nodes[0].masks, (std::vector<uint32_t>{0, 2}));
  EXPECT_EQ(nodes[1].masks, (std::vector<uint32_t>{1, 3}));
}

// One object, Gaussians 0..199, on a dense line (one DBSCAN cluster). Views 0-2 hold whole-object
// masks; views 3 and 4 split it SAM-style into a part A = 0..109 and a sliver (110..139 in view 3,
// 140..169 in view 4: no sliver is seen twice, so none becomes an instance), the rest unlabelled.
// The whole masks look under-segmented (split in 2 of 5 visible frames); re-judgement sees that
// their instance-covered Gaussians all lie in A's instance, restores them, and the object comes out
// whole.
TEST(Rejudge, WholeObjectMaskSplitByPartMasksIsRestored) {
  const TrackerSet set = MakeSet(5, 200,
                                 {{0, 1, 0, 200},
                                  {1, 1, 0, 200},
                                  {2, 1, 0, 200},
                                  {3, 1, 0, 110},
                                  {3, 2, 110, 140},
                                  {4, 1, 0, 110},
                                  {4, 2, 140, 170}});
  const GaussianCloud cloud = LineCloud(200, 200);
  DecompositionOptions options;
  const MaskJudgement judged = JudgeTrackers(set, options);
  for (int t = 0; t < 3; ++t) ASSERT_TRUE(judged.undersegmented[t]) << t;
  std::vector<Instance> instances =
      InstancesWithFlags(set, judged, judged.undersegmented, cloud, options);
  ASSERT_EQ(instances.size(), 1u);  // the part A only
  EXPECT_EQ(instances[0].gaussians.size(), 110u);
  std::vector<uint8_t> flags = judged.undersegmented;
  EXPECT_EQ(RejudgeUndersegmented(set, instances, options, &flags), 3);
  for (int t = 0; t < 3; ++t) EXPECT_FALSE(flags[t]) << t;
  instances = InstancesWithFlags(set, judged, flags, cloud, options);
  ASSERT_EQ(instances.size(), 1u);
  EXPECT_EQ(instances[0].gaussians.size(), 200u);
}

// One object, Gaussians 0..199, whose part masks never repeat: views 0-2 hold whole-object masks,
// views 3 and 4 mask two different pairs of small parts (each part seen once, so none becomes an
// instance). Split in 2 of 5 frames, every whole mask is flagged, and no instance covers any of
// them. The masks hold the object in every frame that traces it and split it in a minority: the
// whole masks are restored and the object comes out whole. A background patch (200..259) that a
// stray mask covers in view 0 and two stray masks in view 1 is held in 2 of the 5 frames that trace
// it and stays flagged.
TEST(Rejudge, AnObjectWhoseEveryWholeMaskIsFlaggedIsRestoredStrayBackgroundIsNot) {
  const TrackerSet set = MakeSet(5, 260,
                                 {{0, 1, 0, 200},
                                  {0, 2, 200, 260},
                                  {1, 1, 0, 200},
                                  {1, 2, 200, 230},
                                  {1, 3, 230, 260},
                                  {2, 1, 0, 200},
                                  {3, 1, 0, 40},
                                  {3, 2, 160, 200},
                                  {4, 1, 40, 80},
                                  {4, 2, 120, 160}});
  const GaussianCloud cloud = LineCloud(260, 200);
  DecompositionOptions options;
  const MaskJudgement judged = JudgeTrackers(set, options);
  for (uint32_t t : {0u, 1u, 2u, 5u}) ASSERT_TRUE(judged.undersegmented[t]) << t;  // 1: stray
  EXPECT_EQ(judged.frames[0].traced, 5);
  EXPECT_EQ(judged.frames[0].visible, 5);
  EXPECT_EQ(judged.frames[0].split, 2);
  EXPECT_EQ(judged.frames[1].traced, 5);
  EXPECT_EQ(judged.frames[1].visible, 2);
  std::vector<Instance> instances =
      InstancesWithFlags(set, judged, judged.undersegmented, cloud, options);
  ASSERT_TRUE(instances.empty());
  std::vector<uint8_t> flags = judged.undersegmented;
  EXPECT_EQ(RejudgeUndersegmented(set, instances, options, &flags), 0);  // no counts: released rule
  DecompositionOptions off = options;
  off.uncovered_min_labelled = 2.0;
  EXPECT_EQ(RejudgeUndersegmented(set, instances, off, &flags, &judged.frames), 0);
  EXPECT_EQ(RejudgeUndersegmented(set, instances, options, &flags, &judged.frames), 3);
  for (uint32_t t : {0u, 2u, 5u}) EXPECT_FALSE(flags[t]) << t;
  EXPECT_TRUE(flags[1]);  // the stray mask
  instances = InstancesWithFlags(set, judged, flags, cloud, options);
  ASSERT_EQ(instances.size(), 1u);
  EXPECT_EQ(instances[0].gaussians.size(), 200u);
}

// The point filter (detected / appear > 0.5) and merges: object A (Gaussians 0..99) has its own
// masks in views 0 and 1 and lies in a mask merged with its neighbour B (0..199, judged
// under-segmented) in views 2-4, where A's node is visible. Counting those frames, A's points are
// detected in 2 of 5 and the whole object is filtered away (the released code); a merged mask says
// nothing about which object a point belongs to, so they do not count and A is kept whole.
TEST(PostProcess, FramesWhereAPointLiesInAMergedMaskDoNotCountAgainstIt) {
  const TrackerSet set = MakeSet(
      5, 200, {{0, 1, 0, 100}, {1, 1, 0, 100}, {2, 1, 0, 200}, {3, 1, 0, 200}, {4, 1, 0, 200}});
  const GaussianCloud cloud = LineCloud(200, 200);
  MaskNode node{{0, 1}, ViewSet(5), {}};
  for (int v = 0; v < 5; ++v) node.visible.Set(v);
  const std::vector<uint8_t> flags = {0, 0, 1, 1, 1};
  DecompositionOptions options;
  const std::vector<Instance> kept = BuildInstances(set, {node}, cloud, options, &flags);
  ASSERT_EQ(kept.size(), 1u);
  EXPECT_EQ(kept[0].gaussians.size(), 100u);
  options.filter_skips_merged_frames = false;
  EXPECT_TRUE(BuildInstances(set, {node}, cloud, options, &flags).empty());
  // Without the judgement (no flags given) the frames count as before.
  EXPECT_TRUE(BuildInstances(set, {node}, cloud, DecompositionOptions{}).empty());
}

// A true merge stays flagged: a mask over A (0..99) and B (100..199) whose Gaussians lie half in
// each instance; and a mask too little of which lies in any instance is not judged at all.
TEST(Rejudge, MergedMaskAndMostlyUncoveredMaskStayUndersegmented) {
  const TrackerSet set = MakeSet(1, 400, {{0, 1, 0, 200}, {0, 2, 200, 400}});
  std::vector<Instance> instances(2);
  for (uint32_t g = 0; g < 100; ++g) instances[0].gaussians.push_back(g);
  for (uint32_t g = 100; g < 200; ++g) instances[1].gaussians.push_back(g);
  for (uint32_t g = 200; g < 280; ++g) instances[0].gaussians.push_back(g);  // 40 % of mask 2
  std::sort(instances[0].gaussians.begin(), instances[0].gaussians.end());
  std::vector<uint8_t> flags = {1, 1};
  DecompositionOptions options;  // remedy_ratio 0.8, rejudge_min_coverage 0.5
  EXPECT_EQ(RejudgeUndersegmented(set, instances, options, &flags), 0);
  EXPECT_EQ(flags, (std::vector<uint8_t>{1, 1}));
  options.rejudge_min_coverage = 0.4;  // now mask 2 is covered enough, and wholly by instance 1
  EXPECT_EQ(RejudgeUndersegmented(set, instances, options, &flags), 1);
  EXPECT_EQ(flags, (std::vector<uint8_t>{1, 0}));
}

// A flagged mask over A (0..199, an instance) and 60 more Gaussians (200..259) in no instance:
// mostly inside A, so the re-judgement would restore it. When the 60 are another object that
// masks hold apart from A in most frames (its own masks in views 0-3, merged with A in views 4
// and 5), the mask keeps its flag; when they are the rest of A's object, masked together with it
// in most frames (whole masks in views 0-3, a part split in view 4), it is restored.
TEST(Rejudge, AMaskWhosePartOutsideEveryInstanceIsAnotherObjectStaysFlagged) {
  std::vector<Instance> instances(1);
  for (uint32_t g = 0; g < 200; ++g) instances[0].gaussians.push_back(g);
  DecompositionOptions options;
  {
    std::vector<HandMask> masks;
    for (int v = 0; v < 4; ++v) {
      masks.push_back({v, 1, 0, 200});
      masks.push_back({v, 2, 200, 260});
    }
    masks.push_back({4, 1, 0, 260});
    masks.push_back({5, 1, 0, 260});
    const TrackerSet set = MakeSet(6, 260, masks);
    const uint32_t merged = 8;  // view 4's mask
    std::vector<uint8_t> flags(set.trackers.size(), 0);
    flags[merged] = 1;
    DecompositionOptions off = options;
    off.rejudge_remainder_max_apart = 1.0;
    std::vector<uint8_t> released = flags;
    EXPECT_EQ(RejudgeUndersegmented(set, instances, off, &released), 1);
    EXPECT_EQ(RejudgeUndersegmented(set, instances, options, &flags), 0);
    EXPECT_TRUE(flags[merged]);
  }
  {
    std::vector<HandMask> masks;
    for (int v = 0; v < 4; ++v) masks.push_back({v, 1, 0, 260});
    masks.push_back({4, 1, 0, 200});
    masks.push_back({4, 2, 200, 260});
    const TrackerSet set = MakeSet(5, 260, masks);
    std::vector<uint8_t> flags(set.trackers.size(), 0);
    flags[0] = 1;
    EXPECT_EQ(RejudgeUndersegmented(set, instances, options, &flags), 1);
    EXPECT_FALSE(flags[0]);
  }
}

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

TEST(MaskGraph, ObserverScheduleFollowsNumpyPercentiles) {
  // Three trackers visible in {0,1,2}, {0,1}, {3}: the non-zero entries of V V^T (both triangles
  // and the diagonal) are 1, 2, 2, 2, 3 -> numpy percentiles 95, 90, ..., 5 by linear
  // interpolation; the 0th percentile is 1 (<= 1 below the median): the schedule stops there.
  MaskJudgement j;
  j.visible.assign(3, ViewSet(4));
  for (int v : {0, 1, 2}) j.visible[0].Set(v);
  for (int v : {0, 1}) j.visible[1].Set(v);
  j.visible[2].Set(3);
  const std::vector<double> schedule = ObserverSchedule(j, {0, 1, 2});
  ASSERT_EQ(schedule.size(), 19u);
  EXPECT_NEAR(schedule[0], 2.8, 1e-12);      // numpy.percentile([1, 2, 2, 2, 3], 95)
  EXPECT_NEAR(schedule[1], 2.6, 1e-12);      // 90th
  EXPECT_NEAR(schedule[10], 2.0, 1e-12);     // 45th
  EXPECT_NEAR(schedule.back(), 1.2, 1e-12);  // 5th
}

TEST(PostProcess, DbscanSplitsClustersAndDropsFloaters) {
  std::mt19937 rng(3);
  std::normal_distribution<float> n(0.0f, 0.01f);
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < 60; ++i) points.emplace_back(n(rng), n(rng), n(rng));
  for (int i = 0; i < 60; ++i) points.emplace_back(1.0f + n(rng), n(rng), n(rng));
  points.emplace_back(0.5f, 0.5f, 0.5f);  // floaters
  points.emplace_back(-0.7f, 0.2f, 0.0f);
  const std::vector<int> label = Dbscan(points, 0.05f, 4);
  for (int i = 1; i < 60; ++i) EXPECT_EQ(label[i], label[0]);
  for (int i = 61; i < 120; ++i) EXPECT_EQ(label[i], label[60]);
  EXPECT_NE(label[0], label[60]);
  EXPECT_GE(label[0], 0);
  EXPECT_EQ(label[120], -1);
  EXPECT_EQ(label[121], -1);
}

// Textbook O(n^2) DBSCAN core-point clustering: the reference for the grid implementation.
std::vector<int> BruteCoreClusters(const std::vector<Eigen::Vector3f>& p, float eps,
                                   int min_points) {
  const size_t n = p.size();
  std::vector<uint8_t> core(n, 0);
  for (size_t i = 0; i < n; ++i) {
    int count = 0;
    for (size_t j = 0; j < n; ++j) count += (p[i] - p[j]).norm() <= eps;
    core[i] = count >= min_points;
  }
  std::vector<int> label(n, -1);
  int next = 0;
  for (size_t i = 0; i < n; ++i) {
    if (!core[i] || label[i] >= 0) continue;
    std::vector<size_t> stack = {i};
    label[i] = next;
    while (!stack.empty()) {
      const size_t a = stack.back();
      stack.pop_back();
      for (size_t b = 0; b < n; ++b) {
        if (core[b] && label[b] < 0 && (p[a] - p[b]).norm() <= eps) {
          label[b] = next;
          stack.push_back(b);
        }
      }
    }
    ++next;
  }
  return label;
}

TEST(PostProcess, GridDbscanMatchesBruteForceOnCorePoints) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int trial = 0; trial < 6; ++trial) {
    std::vector<Eigen::Vector3f> p;
    for (int c = 0; c < 5; ++c) {  // blobs of varying density plus uniform clutter
      const Eigen::Vector3f center(u(rng), u(rng), u(rng));
      const float spread = 0.02f + 0.05f * u(rng);
      for (int i = 0; i < 80; ++i)
        p.push_back(center + spread * Eigen::Vector3f(u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f));
    }
    for (int i = 0; i < 100; ++i) p.emplace_back(u(rng), u(rng), u(rng));
    const float eps = 0.03f + 0.02f * trial;
    const std::vector<int> fast = Dbscan(p, eps, 4), ref = BruteCoreClusters(p, eps, 4);
    for (size_t i = 0; i < p.size(); ++i) {
      if (ref[i] >= 0) {
        EXPECT_EQ(fast[i], ref[i]) << "core point " << i << " trial " << trial;
      }
      // A non-core point is noise exactly when no core point lies within eps.
      bool near_core = false;
      for (size_t j = 0; j < p.size(); ++j) near_core |= ref[j] >= 0 && (p[i] - p[j]).norm() <= eps;
      EXPECT_EQ(fast[i] >= 0, ref[i] >= 0 || near_core) << i;
    }
  }
}

// End to end on small synthetic scenes; returns the evaluation of the decomposition.
ClickEvaluation DecomposeSynthetic(const std::string& noise, uint64_t seed) {
  const instascene::testing::ScopedTempDir temp("decomp_" + noise + std::to_string(seed));
  const std::string dir = temp.Sub("scene");
  ClutterOptions scene_options = *ClutterPreset("small");
  scene_options.seed = seed;
  absl::StatusOr<ClutterScene> scene = GenerateClutterScene(scene_options);
  EXPECT_TRUE(scene.ok());
  SceneWriteOptions write;
  write.mask_noise = noise;
  write.seed = seed;
  EXPECT_TRUE(WriteClutterScene(*scene, dir, write).ok());
  absl::StatusOr<Scene> read = ReadScene(dir);
  EXPECT_TRUE(read.ok());
  absl::StatusOr<DecompositionResult> result =
      Decompose(*read, scene->cloud, DecompositionOptions{});
  EXPECT_TRUE(result.ok()) << result.status();
  EXPECT_TRUE(WriteDecomposition(dir + "/decomposition", *read, scene->cloud, *result).ok());
  absl::StatusOr<ClickEvaluation> eval =
      EvaluateResultDirectory(dir, dir + "/decomposition", ClickEvalOptions{});
  EXPECT_TRUE(eval.ok()) << eval.status();
  return *eval;
}

// Every object visible (>= 20 GT pixels) in at least `min_views` views is recovered: some
// instance overlaps its observed Gaussians with IoU > 0.5.
void ExpectWellSeenObjectsRecovered(const ClickEvaluation& eval, int min_views) {
  int checked = 0;
  for (const ObjectClickScore& o : eval.objects) {
    if (o.views < min_views) continue;
    ++checked;
    EXPECT_GT(eval.instances.best_iou.at(o.id), 0.5)
        << o.name << " seen in " << o.views << " views";
  }
  EXPECT_GE(checked, 5);
}

TEST(Decompose, RecoversEveryWellSeenObjectWithoutNoise) {
  for (uint64_t seed : {1, 2}) {
    const ClickEvaluation eval = DecomposeSynthetic("none", seed);
    ExpectWellSeenObjectsRecovered(eval, 6);
    EXPECT_GT(eval.miou, 0.7);
    EXPECT_DOUBLE_EQ(eval.instances.precision, 1.0);
  }
}

TEST(Decompose, RecoversEveryWellSeenObjectAtLowNoise) {
  for (uint64_t seed : {1, 2}) ExpectWellSeenObjectsRecovered(DecomposeSynthetic("low", seed), 6);
}

}  // namespace
}  // namespace instascene::decomposition
