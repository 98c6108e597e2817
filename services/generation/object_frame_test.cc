#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "common/synth/primitives.h"
#include "common/synth/surfels.h"
#include "services/generation/testing/partial_objects.h"

namespace instascene::generation {
namespace {

using namespace testing;  // NOLINT(build/namespaces): the test scenes

TEST(ObjectFrame, UpFromTheSupportAndSupportHeight) {
  const PartialObject scene = MakePartialObject(Bottle(), 4000, 3);
  auto split = SplitInstance(scene.labels, 1, 50);
  ASSERT_TRUE(split.ok());
  const ObjectFrame frame = ComputeObjectFrame(scene.cloud, *split, scene.cameras);
  EXPECT_GT(frame.up.z(), std::cos(2 * kPi / 180));  // within 2 degrees of the truth
  ASSERT_TRUE(frame.has_support);
  EXPECT_NEAR(frame.support_height, 0.0f, 0.005f);
  EXPECT_GT(frame.spacing, 0);
}

// A bottle with a box (label 2) standing 2 mm beside it at +x: the bottle's surfels facing the box
// are surrounded by its label, those on the far side and those over the bare table are not.
TEST(ObjectFrame, NeighbourLabelledMarksTheSurfelsFacingATouchingNeighbour) {
  PartialObject scene = MakePartialObject(Bottle(), 4000, 5);
  ShapeSpec box;
  box.kind = ShapeKind::kBox;
  box.size = {0.04f, 0.04f, 0.1f};
  TriangleMesh mesh = MakeShapeMesh(box);
  Rigid3d shift;
  shift.translation = {0.072, 0.0, 0.0};
  mesh.Transform(shift);
  std::mt19937_64 rng(5);
  const size_t before = scene.cloud.size();
  AppendSurfels(mesh, 3000, Appearance{}, SurfelSampling{}, rng, &scene.cloud);
  scene.labels.resize(before, 0);
  scene.labels.resize(scene.cloud.size(), 2);
  auto split = SplitInstance(scene.labels, 1, 50);
  ASSERT_TRUE(split.ok());
  const ObjectFrame frame = ComputeObjectFrame(scene.cloud, *split, scene.cameras);
  const std::vector<uint8_t> marked = NeighbourLabelled(scene.cloud, scene.labels, *split, frame);
  ASSERT_EQ(marked.size(), split->instance.size());
  size_t facing = 0, facing_marked = 0, far_marked = 0;
  for (size_t i = 0; i < marked.size(); ++i) {
    const Eigen::Vector3f p(&scene.cloud.positions[3 * split->instance[i]]);
    if (p.x() > 0.045f && std::abs(p.y()) < 0.01f && p.z() > 0.01f && p.z() < 0.09f) {
      ++facing;
      facing_marked += marked[i];
    }
    if (p.x() < 0.02f) far_marked += marked[i];
  }
  ASSERT_GT(facing, 10u);
  EXPECT_GT(facing_marked, 0.9 * facing);
  EXPECT_EQ(far_marked, 0u);
  // Without the neighbour's label (background), nothing is marked.
  std::fill(scene.labels.begin() + before, scene.labels.end(), 0u);
  const std::vector<uint8_t> none = NeighbourLabelled(scene.cloud, scene.labels, *split, frame);
  EXPECT_EQ(std::count(none.begin(), none.end(), 1), 0);
  // Nor when the box carries the bottle's own label outside the instance (as strays that left it
  // do): the split above already holds the box's surfels as occluders.
  std::fill(scene.labels.begin() + before, scene.labels.end(), 1u);
  const std::vector<uint8_t> own = NeighbourLabelled(scene.cloud, scene.labels, *split, frame);
  EXPECT_EQ(std::count(own.begin(), own.end(), 1), 0);
}

// A cone whose top is bare but for two surfels on its tip (spread by area, a sharp tip's surfels
// stand apart): the stray removal cuts them off and they return; a neighbour's surfel beside the
// top and a floater high above it stay out.
TEST(ObjectFrame, ATipTheStrayRemovalCutOffReturns) {
  ShapeSpec cone;
  cone.kind = ShapeKind::kCone;
  cone.size = {0.036f, 0, 0.094f};
  PartialObject scene = MakePartialObject(MakeShapeMesh(cone), 1200, 7);
  std::vector<uint32_t> keep, labels;
  for (uint32_t g = 0; g < scene.cloud.size(); ++g) {
    if (scene.labels[g] == 1 && scene.cloud.positions[3 * g + 2] > 0.083f) continue;
    keep.push_back(g);
    labels.push_back(scene.labels[g]);
  }
  scene.cloud = scene.cloud.Subset(keep);
  scene.labels = labels;
  const size_t before = scene.cloud.size();
  AppendObjectSurfelsAt({{0, 0, 0.094f},
                         {0.001f, 0, 0.091f},  // the tip
                         {0.03f, 0, 0.087f},   // a neighbour's, beside the top
                         {0, 0, 0.14f}},       // a floater
                        &scene);
  auto split = SplitInstance(scene.labels, 1, 50);
  ASSERT_TRUE(split.ok());
  const StrayComponents strays = RemoveStrayGaussians(scene.cloud, &*split);
  auto in = [](const std::vector<uint32_t>& v, uint32_t g) {
    return std::binary_search(v.begin(), v.end(), g);
  };
  for (uint32_t g = before; g < before + 4; ++g) ASSERT_TRUE(in(split->occluders, g)) << g;
  const size_t removed = split->outliers;
  const ObjectFrame frame = ComputeObjectFrame(scene.cloud, *split, scene.cameras);
  EXPECT_EQ(ReturnTips(scene.cloud, frame, strays, &*split), 2u);
  EXPECT_TRUE(in(split->instance, before) && in(split->instance, before + 1));
  EXPECT_TRUE(in(split->occluders, before + 2) && in(split->occluders, before + 3));
  EXPECT_FALSE(in(split->occluders, before) || in(split->instance, before + 2));
  EXPECT_TRUE(std::is_sorted(split->instance.begin(), split->instance.end()));
  EXPECT_EQ(split->outliers, removed - 2);
  EXPECT_EQ(split->instance.size() + split->occluders.size(), scene.cloud.size());
  // Returned once: nothing more the second time.
  EXPECT_EQ(
      ReturnTips(scene.cloud, ComputeObjectFrame(scene.cloud, *split, scene.cameras), {}, &*split),
      0u);
}

// A segmentation that gave the bottle the table's surfels around its base: they leave the
// instance (the bottle's own surfels all stay), and the support and bottom are the table's.
TEST(ObjectFrame, TheSupportsSurfelsAroundTheBaseLeaveTheInstance) {
  PartialObject scene = MakePartialObject(Bottle(), 4000, 3);
  auto clean = SplitInstance(scene.labels, 1, 50);
  ASSERT_TRUE(clean.ok());
  size_t ring = 0;
  for (uint32_t g = 0; g < scene.cloud.size(); ++g) {
    const Eigen::Vector3f p(&scene.cloud.positions[3 * g]);
    const float r = Eigen::Vector2f(p.x(), p.y()).norm();
    if (scene.labels[g] == 0 && std::abs(p.z()) < 1e-4f && r < 0.1f) {
      scene.labels[g] = 1;
      ++ring;
    }
  }
  ASSERT_GT(ring, 5u);
  auto split = SplitInstance(scene.labels, 1, 50);
  ASSERT_TRUE(split.ok());
  const ObjectFrame frame = ComputeObjectFrame(scene.cloud, *split, scene.cameras);
  ASSERT_TRUE(frame.has_support);
  EXPECT_EQ(RemoveSupportSurfels(scene.cloud, frame, &*split), ring);
  EXPECT_EQ(split->instance, clean->instance);
  EXPECT_EQ(split->outliers, ring);
  EXPECT_EQ(split->instance.size() + split->occluders.size(), scene.cloud.size());
  const ObjectFrame again = ComputeObjectFrame(scene.cloud, *split, scene.cameras);
  EXPECT_NEAR(again.support_height, 0.0f, 0.005f);
  EXPECT_EQ(RemoveSupportSurfels(scene.cloud, again, &*split), 0u);  // nothing more to move
}

// The table near the bottle is hidden (no surfel within 60 cm) and a neighbour's face, tilted 30
// degrees, lies beside it: no surfel near the object shows its support. The up is still the
// table's (the scene's support), neither the face's nor the cameras' mean up (22 degrees off
// here: what the frame fell back to before the scene's up).
TEST(ObjectFrame, UpIsTheScenesSupportNotANeighboursTiltedFace) {
  PartialObject scene = MakePartialObject(Bottle(), 4000, 3);
  std::vector<uint32_t> keep, labels;
  for (uint32_t g = 0; g < scene.cloud.size(); ++g) {
    const Eigen::Vector3f p(&scene.cloud.positions[3 * g]);
    if (scene.labels[g] == 0 && Eigen::Vector2f(p.x(), p.y()).norm() < 0.6f) continue;
    keep.push_back(g);
    labels.push_back(scene.labels[g]);
  }
  GaussianCloud cloud = scene.cloud.Subset(keep);
  TriangleMesh face = MakeRectangle(0.2f, 0.2f, 4, 4);
  const Eigen::Matrix3f tilt = Eigen::AngleAxisf(30 * kPi / 180, Eigen::Vector3f::UnitX()).matrix();
  for (Eigen::Vector3f& v : face.vertices) v = tilt * v + Eigen::Vector3f(0.16f, 0, 0.02f);
  std::mt19937_64 rng(4);
  AppendSurfels(face, 1500, Appearance{}, SurfelSampling{}, rng, &cloud);
  labels.resize(cloud.size(), 0);
  auto split = SplitInstance(labels, 1, 50);
  ASSERT_TRUE(split.ok());
  const ObjectFrame frame = ComputeObjectFrame(cloud, *split, scene.cameras);
  EXPECT_GT(frame.up.z(), std::cos(2 * kPi / 180)) << frame.up.transpose();
}

// The frame of a partly seen bottle (instance 1) beside `count` surfels of `surface` labelled
// `label`.
ObjectFrame BottleFrameBeside(const TriangleMesh& surface, size_t count, uint32_t label,
                              size_t bottle_count, uint64_t seed) {
  PartialObject scene = MakePartialObject(Bottle(), bottle_count, 3);
  std::mt19937_64 rng(seed);
  AppendSurfels(surface, count, Appearance{}, SurfelSampling{}, rng, &scene.cloud);
  scene.labels.resize(scene.cloud.size(), label);
  auto split = SplitInstance(scene.labels, 1, 50);
  EXPECT_TRUE(split.ok());
  return split.ok() ? ComputeObjectFrame(scene.cloud, *split, scene.cameras) : ObjectFrame{};
}

// A low block's top slanted 7 degrees 14.5-29.5 cm from a bottle's axis (most of it within two of
// the bottle's radii, 27 cm: about its half-height; beyond twice its horizontal radius, 10-12 cm),
// with more surfels than the table shows there: the bottle's support is still the table. With the
// radius as the reach and a 10-degree mode the two mixed and the up came out 5 degrees off (as seed
// 44's touching bottles were tilted; RESULTS.md "Object frames: the object's own footprint").
TEST(ObjectFrame, ANeighboursSlantedTopBeyondTheFootprintDoesNotTiltTheUp) {
  TriangleMesh top = MakeRectangle(0.15f, 0.15f, 4, 4);
  const Eigen::Matrix3f tilt = Eigen::AngleAxisf(7 * kPi / 180, Eigen::Vector3f::UnitY()).matrix();
  for (Eigen::Vector3f& v : top.vertices) v = tilt * v + Eigen::Vector3f(-0.22f, 0, 0.004f);
  const ObjectFrame frame = BottleFrameBeside(top, 2500, 0, 4000, 5);
  EXPECT_GT(frame.up.z(), std::cos(0.5f * kPi / 180)) << frame.up.transpose();
}

// The support height found beside (or under) a square floor of `side` centred at `at`, 800 of
// its surfels labelled `label`, and a bottle of `bottle_count` surfels; NaN without a support.
float SupportWithAFloor(float side, const Eigen::Vector3f& at, uint32_t label,
                        size_t bottle_count) {
  TriangleMesh floor = MakeRectangle(side, side, 2, 2);
  for (Eigen::Vector3f& v : floor.vertices) v += at;
  const ObjectFrame frame = BottleFrameBeside(floor, 800, label, bottle_count, 7);
  return frame.has_support ? frame.support_height : std::numeric_limits<float>::quiet_NaN();
}

// A neighbour's inner floor (a bowl's, 6 mm above the table, labelled 2) dense beside the bottle:
// more surfels per bin than a quarter of the table's around it, and higher. The support surrounds
// the object; the floor lies to one side.
TEST(ObjectFrame, TheSupportSurroundsTheObjectNotANeighboursFloorBesideIt) {
  EXPECT_NEAR(SupportWithAFloor(0.06f, Eigen::Vector3f(0.12f, 0.0f, 0.006f), 2, 12000), 0.0f,
              0.002f);
}

// The object's own inner floor (a mug's, 5 mm above the table, that the segmentation left out
// of the instance: label 0) inside its footprint, around its centre: it surrounds the centre in
// every sector, dense and higher than the table. The support surrounds the object outside its
// footprint (seed 51's mug_7 stood on its own floor, 5.6 mm too short).
TEST(ObjectFrame, TheSupportIsNotTheObjectsOwnFloor) {
  EXPECT_NEAR(SupportWithAFloor(0.04f, Eigen::Vector3f(0.0f, 0.0f, 0.005f), 0, 4000), 0.0f, 0.002f);
}

}  // namespace
}  // namespace instascene::generation
