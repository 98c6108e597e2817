#include "services/generation/symmetry.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include <gtest/gtest.h>

#include "common/synth/primitives.h"
#include "services/generation/testing/partial_objects.h"

namespace instascene::generation {
namespace {

using namespace testing;  // NOLINT(build/namespaces): the test scenes

TEST(Symmetry, RecoversTheAxisOfAPartlySeenBottle) {
  // 10-70 % occlusion: cameras over 140, 100 and 60 degrees of azimuth.
  for (double half_angle : {70.0, 50.0, 30.0}) {
    const Detected d = Detect(MakePartialObject(Bottle(), 4000, 5, half_angle));
    const SymmetryHypothesis* axis = nullptr;
    for (const SymmetryHypothesis& h : d.hypotheses) {
      if (h.kind == SymmetryKind::kAxis) axis = &h;
    }
    ASSERT_NE(axis, nullptr);
    EXPECT_TRUE(axis->accepted) << half_angle << ": " << axis->Describe();
    EXPECT_GT(axis->direction.z(), std::cos(2 * kPi / 180)) << axis->Describe();
    // The true axis is the z axis through the origin.
    EXPECT_LT(Eigen::Vector2f(axis->point.x(), axis->point.y()).norm(), 0.004f) << axis->Describe();
  }
}

// A mug's handle pulls the circle fit towards itself, and agreement (images within the match
// distance) is flat over millimetres; the alignment cost places the axis on the body's.
TEST(Symmetry, AMugsAxisIsTheBodysNotPulledByTheHandle) {
  ShapeSpec spec;
  spec.kind = ShapeKind::kMug;
  spec.size = {0.05f, 0, 0.1f};
  for (uint64_t seed : {11u, 12u, 13u, 14u}) {
    const PartialObject scene = MakePartialObject(MakeShapeMesh(spec, 48), 4000, seed, 100);
    auto offset = [&](bool refine) {
      SymmetryOptions options;
      options.refine_axis = refine;
      for (const SymmetryHypothesis& h : Detect(scene, options).hypotheses) {
        if (h.kind == SymmetryKind::kAxis) return Eigen::Vector2f(h.point.x(), h.point.y()).norm();
      }
      return 1.0f;
    };
    // The body's axis is the z axis: 4.0-4.3 mm off by agreement alone, 0.6-1.1 mm refined.
    EXPECT_GT(offset(false), 0.003f) << seed;
    EXPECT_LT(offset(true), 0.0015f) << seed;
  }
}

// A box turned by anything but its own turns puts its corners into space the views saw empty: its
// axis is n-fold (4 for a square footprint, 2 for a rectangle, also a nearly square one whose
// quarter turns overhang by less than the match distance) through its centre, not a solid of
// revolution; a bottle's stays continuous.
TEST(Symmetry, ABoxHasAnNFoldAxisThroughItsCentre) {
  const Eigen::Matrix3d yaw = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).matrix();
  for (const auto& [size, order] : std::vector<std::pair<Eigen::Vector3f, int>>{
           {{0.14f, 0.14f, 0.07f}, 4}, {{0.11f, 0.075f, 0.14f}, 2}, {{0.083f, 0.096f, 0.16f}, 2}}) {
    ShapeSpec spec;
    spec.kind = ShapeKind::kBox;
    spec.size = size;
    TriangleMesh box = MakeShapeMesh(spec);
    box.Transform({yaw, Eigen::Vector3d::Zero()});
    const Detected d = Detect(MakePartialObject(box, 5000, 9));
    const SymmetryHypothesis* axis = nullptr;
    for (const SymmetryHypothesis& h : d.hypotheses) {
      if (h.kind == SymmetryKind::kAxis) axis = &h;
    }
    ASSERT_NE(axis, nullptr);
    EXPECT_EQ(axis->order, order) << axis->Describe();
    EXPECT_EQ(axis->copies, order - 1);
    EXPECT_TRUE(axis->accepted) << axis->Describe();
    EXPECT_LT(Eigen::Vector2f(axis->point.x(), axis->point.y()).norm(), 0.004f) << axis->Describe();
  }
  const Detected bottle = Detect(MakePartialObject(Bottle(), 4000, 5));
  for (const SymmetryHypothesis& h : bottle.hypotheses) {
    if (h.kind == SymmetryKind::kAxis) {
      EXPECT_EQ(h.order, 0) << h.Describe();
    }
  }
}

// A vertical axis scored at 11 turns of 30 degrees: agree / decided images per turn.
SymmetryHypothesis AxisScoredPerTurn(const std::vector<int>& agree,
                                     const std::vector<int>& decided) {
  SymmetryHypothesis axis;
  axis.kind = SymmetryKind::kAxis;
  axis.copies = 11;
  axis.copy_agree = agree;
  for (int k = 0; k < 11; ++k) axis.copy_contradict.push_back(decided[k] - agree[k]);
  return axis;
}

// A continuous axis must agree at every turn. Seed 44's box_7 (301 surfels, a third of them
// labelled, seen in few views): 11 of 16 decided images of its 270-degree turn agree, its whole
// 94.9 % over 234 decided, so the whole alone accepted a revolution and its completion stood 5-13
// mm off the box in space views saw empty. A mug's handle costs every turn alike (89 %), and a turn
// decided for a few images only says too little.
TEST(Symmetry, ASolidOfRevolutionAgreesAtEveryTurn) {
  const SymmetryHypothesis box = AxisScoredPerTurn({52, 17, 11, 14, 15, 9, 17, 15, 11, 14, 47},
                                                   {54, 18, 12, 14, 15, 9, 17, 15, 16, 17, 47});
  const SymmetryOptions options;
  EXPECT_FALSE(AgreesAtEveryTurn(box, options));
  SymmetryHypothesis mug = box;
  mug.copy_agree.assign(11, 267);
  mug.copy_contradict.assign(11, 33);  // 89 % at every turn
  EXPECT_TRUE(AgreesAtEveryTurn(mug, options));
  SymmetryHypothesis sparse = mug;
  sparse.copy_agree[4] = 2;
  sparse.copy_contradict[4] = 7;  // 9 images decided: too few to reject
  EXPECT_TRUE(AgreesAtEveryTurn(sparse, options));
  sparse.copy_contradict[4] = 8;  // 10
  EXPECT_FALSE(AgreesAtEveryTurn(sparse, options));
}

// A rectangular box with a third of its surfels unlabelled (mask noise, seed 85): per turn of 30
// degrees, agree / decided as scored there. Its third turns (120 and 240 degrees) agree 0.89 /
// 0.88 and the other turns on the whole 0.69, so it passed as 3-fold and was completed as a
// six-sided block 12 % too wide; its half turn agrees 0.99, better than either: 2-fold.
TEST(Symmetry, AnNFoldAxisAgreesBetterThanEveryOtherTurn) {
  SymmetryHypothesis box =
      AxisScoredPerTurn({220, 150, 81, 214, 155, 191, 154, 195, 87, 165, 237},
                        {314, 272, 185, 241, 168, 193, 197, 221, 170, 261, 339});
  box.scored = 300;
  SymmetryOptions options;
  EXPECT_EQ(DiscreteOrder(box, options), 2);
  options.order_outagrees_other_turns = false;
  EXPECT_EQ(DiscreteOrder(box, options), 3);
  SymmetryHypothesis square = box;  // quarter turns agree 0.98, the others 0.5
  for (int k = 0; k < 11; ++k) {
    square.copy_agree[k] = (k + 1) % 3 == 0 ? 196 : 100;
    square.copy_contradict[k] = 200 - square.copy_agree[k];
  }
  EXPECT_EQ(DiscreteOrder(square, SymmetryOptions{}), 4);
}

// A box turned by 17.19 degrees: the plane grid's 5-degree steps leave its best mirror plane 2.2
// or 2.8 degrees off (a mirror doubles that: a far face lands millimetres beside itself); the
// refinement by the alignment cost finds the box's own planes within a degree, through its centre.
TEST(Symmetry, MirrorPlanesAreRefinedBetweenTheGridsSteps) {
  const double yaw_rad = 0.3;
  const Eigen::Matrix3d yaw = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).matrix();
  for (const Eigen::Vector3f& size :
       {Eigen::Vector3f(0.14f, 0.09f, 0.07f), Eigen::Vector3f(0.11f, 0.075f, 0.14f)}) {
    ShapeSpec spec;
    spec.kind = ShapeKind::kBox;
    spec.size = size;
    TriangleMesh box = MakeShapeMesh(spec);
    box.Transform({yaw, Eigen::Vector3d::Zero()});
    const PartialObject scene = MakePartialObject(box, 5000, 9);
    // Degrees between a plane's normal and the nearer of the box's two face normals.
    auto angle_error = [&](const SymmetryHypothesis& h) {
      double best = 180;
      for (double face : {yaw_rad, yaw_rad + kPi / 2}) {
        const double c =
            std::abs(h.direction.x() * std::cos(face) + h.direction.y() * std::sin(face));
        best = std::min(best, std::acos(std::min(1.0, c)) * 180 / kPi);
      }
      return best;
    };
    SymmetryOptions grid_only;
    grid_only.refine_steps = 0;
    for (const auto& [options, max_error, min_error] :
         std::vector<std::tuple<SymmetryOptions, double, double>>{{grid_only, 3.0, 2.0},
                                                                  {SymmetryOptions{}, 1.0, 0.0}}) {
      const Detected d = Detect(scene, options);
      const SymmetryHypothesis* plane = nullptr;
      for (const SymmetryHypothesis& h : d.hypotheses) {
        if (h.kind == SymmetryKind::kPlane) plane = &h;
      }
      ASSERT_NE(plane, nullptr);
      EXPECT_TRUE(plane->accepted) << plane->Describe();
      EXPECT_LT(angle_error(*plane), max_error) << plane->Describe();
      EXPECT_GE(angle_error(*plane), min_error) << plane->Describe();
      // The box's centre (the origin) lies on its planes.
      EXPECT_LT(std::abs(plane->point.dot(plane->direction)), 0.002f) << plane->Describe();
    }
  }
}

// The bar's mid-plane maps the arm behind the bar, where no view looked: nothing contradicts it
// there, and the plane agrees 0.906. Mirror-symmetric shapes agree 0.95 and more; a plane needing
// the default 0.93 (`min_plane_agreement`) is not accepted, one needing 0.85 (the axes' share)
// is.
TEST(Symmetry, AStricterPlaneAgreementRejectsABodySymmetricButForAPart) {
  const PartialObject scene = LBlockArmTowardsTheViews();
  SymmetryOptions lenient;
  lenient.min_plane_agreement = 0.85;
  const Detected d = Detect(scene, lenient);
  const auto plane =
      std::find_if(d.hypotheses.begin(), d.hypotheses.end(),
                   [](const SymmetryHypothesis& h) { return h.kind == SymmetryKind::kPlane; });
  ASSERT_NE(plane, d.hypotheses.end());
  EXPECT_TRUE(plane->accepted) << plane->Describe();
  EXPECT_LT(plane->agreement, 0.93) << plane->Describe();
  for (const SymmetryHypothesis& h : Detect(scene).hypotheses) {
    EXPECT_FALSE(h.accepted) << h.Describe();
  }
}

// The alignment cost leaves out images in unseen space. Near the object the free-space grid's
// margin leaves the space in front of a seen face unseen too, so a plane shifted off the centre
// moved its worst-fitting images (a far face's, mapped past the seen one beyond the match
// distance) out of the cost and won: 1.7 mm off on these boxes (171's box_5: 3.9 mm, its mirrored
// face 8 mm past the seen one). Counted as contradicting where they stand in front of a seen
// surfel, the plane passes through the centre. (Not every grid plane moves: on the same box turned
// by 30 degrees a plane 1.65 mm off stays, or goes to 2.1 mm; docs/RESULTS.md "A mirror plane
// placed against the seen surface".)
TEST(Symmetry, AMirrorPlaneIsPlacedAgainstTheSeenSurface) {
  // A box turned by 45 degrees, every surfel its own; one turned by 60 degrees whose -y face
  // (in its own frame) kept a quarter of its surfels, the rest the background's.
  for (const auto& [yaw_deg, keep_every] : {std::pair{45.0, 1}, std::pair{60.0, 4}}) {
    ShapeSpec spec;
    spec.kind = ShapeKind::kBox;
    spec.size = {0.067f, 0.088f, 0.074f};
    TriangleMesh box = MakeShapeMesh(spec);
    const double yaw = yaw_deg * kPi / 180;
    box.Transform(
        {Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).matrix(), Eigen::Vector3d::Zero()});
    PartialObject scene = MakePartialObject(box, 5000, 9);
    const Eigen::Vector3f face_y(-std::sin(yaw), std::cos(yaw), 0);
    int on_face = 0;
    for (size_t g = 0; g < scene.labels.size(); ++g) {
      const Eigen::Vector3f p(&scene.cloud.positions[3 * g]);
      if (scene.labels[g] == 1 && p.dot(face_y) < -0.04f && p.z() > 0.002f && p.z() < 0.072f &&
          on_face++ % keep_every != 0) {
        scene.labels[g] = 0;
      }
    }
    for (const bool against_surface : {false, true}) {
      SymmetryOptions options;
      options.cost_observed_surface = against_surface;
      const Detected d = Detect(scene, options);
      const auto plane =
          std::find_if(d.hypotheses.begin(), d.hypotheses.end(),
                       [](const SymmetryHypothesis& h) { return h.kind == SymmetryKind::kPlane; });
      ASSERT_NE(plane, d.hypotheses.end());
      EXPECT_TRUE(plane->accepted) << plane->Describe();
      // The box's centre (the origin) lies on its planes.
      const float off_mm = 1000 * std::abs(plane->point.dot(plane->direction));
      if (against_surface) {
        EXPECT_LT(off_mm, 0.3f) << yaw_deg << ": " << plane->Describe();
      } else {
        EXPECT_GT(off_mm, 1.2f) << yaw_deg << ": " << plane->Describe();
      }
    }
  }
}

TEST(Symmetry, ClaimsNoSymmetryOfAnAsymmetricBlock) {
  const Detected d = Detect(MakePartialObject(LBlock(), 5000, 7));
  ASSERT_FALSE(d.hypotheses.empty());
  for (const SymmetryHypothesis& h : d.hypotheses) {
    EXPECT_FALSE(h.accepted) << h.Describe();
  }
}

}  // namespace
}  // namespace instascene::generation
