#include <gtest/gtest.h>

#include <numeric>
#include <random>
#include <tuple>

#include "services/decomposition/decompose.h"
#include "services/decomposition/instance_merging.h"
#include "services/decomposition/mask_graph.h"
#include "services/decomposition/post_process.h"
#include "services/decomposition/testing/hand_trackers.h"
#include "services/decomposition/unlabelled_gaussians.h"

namespace instascene::decomposition {
namespace {

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

}  // namespace
}  // namespace instascene::decomposition
