#include "services/generation/geometric_prior.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "common/geometry/rigid.h"
#include "common/mesh/ray_caster.h"
#include "common/mesh/surfel_mesh.h"
#include "common/synth/cluttered_scene.h"
#include "common/synth/observed_surfels.h"
#include "common/synth/primitives.h"
#include "services/generation/completion.h"
#include "services/generation/seen_through.h"
#include "services/generation/testing/partial_objects.h"

namespace instascene::generation {
namespace {

using namespace testing;  // NOLINT(build/namespaces): the test scenes

// A sphere seen from above and in front: the rotation axis is accepted, and the axis cap closes
// the open lower ring of its revolved surface (a ray from the centre straight down meets a
// surfel), inside the true sphere; without the cap the ray escapes through the underside.
TEST(GeometricPrior, TheAxisCapClosesTheLowerRingOfARevolvedSurface) {
  ShapeSpec spec;
  spec.kind = ShapeKind::kSphere;
  spec.size = {0.08f, 0, 0};  // centred at (0, 0, 0.08), resting on the table
  const PartialObject scene = MakePartialObject(MakeShapeMesh(spec, 48), 3000, 5);
  const PriorFixture fixture(scene);
  ASSERT_TRUE(fixture.ok());
  const PriorInput& input = fixture.input;
  const GaussianCloud& instance = fixture.instance;
  const Eigen::Vector3f centre(0, 0, 0.08f);
  auto closed_below = [&](const PriorOutput& out) {
    auto discs = [](const GaussianCloud& cloud) {
      std::vector<uint32_t> ids(cloud.size());
      for (uint32_t g = 0; g < ids.size(); ++g) ids[g] = g;
      return SurfelDiscs(cloud, ids, SurfelDiscOptions{});
    };
    TriangleMesh object = discs(instance);
    object.Append(discs(out.added));
    auto caster = RayCaster::Create(object);
    EXPECT_TRUE(caster.ok());
    return (*caster)->Cast(centre, -Eigen::Vector3f::UnitZ()).hit;
  };
  GeometricPriorOptions with_cap;
  with_cap.support_cap = false;  // the axis cap alone (support walls would make a skirt)
  auto capped = GeometricPrior(with_cap).Complete(input);
  ASSERT_TRUE(capped.ok()) << capped.status();
  ASSERT_GT(capped->report["added_by"].value("axis_cap", 0), 0) << capped->report.dump();
  EXPECT_TRUE(closed_below(*capped));
  for (size_t g = 0; g < capped->added.size(); ++g) {
    const Eigen::Vector3f p(&capped->added.positions[3 * g]);
    EXPECT_LT((p - centre).norm(), 0.08f + 0.005f) << g;
  }
  GeometricPriorOptions without_cap = with_cap;
  without_cap.axis_cap = false;
  auto open = GeometricPrior(without_cap).Complete(input);
  ASSERT_TRUE(open.ok()) << open.status();
  EXPECT_FALSE(closed_below(*open));
}

// A torus lying on the table, its hole seen through from the cameras: the axis is accepted, but
// the axis cap does not close the hole (no surface of the torus lies above it).
TEST(GeometricPrior, TheAxisCapLeavesATorusHoleOpen) {
  ShapeSpec spec;
  spec.kind = ShapeKind::kTorus;
  spec.size = {0.08f, 0.025f, 0};
  const PartialObject scene = MakePartialObject(MakeShapeMesh(spec, 48), 4000, 7);
  const PriorFixture fixture(scene);
  ASSERT_TRUE(fixture.ok());
  const PriorInput& input = fixture.input;
  GeometricPriorOptions options;
  options.support_cap = false;
  auto out = GeometricPrior(options).Complete(input);
  ASSERT_TRUE(out.ok()) << out.status();
  ASSERT_GT(out->report["added_by"].value("revolved", 0), 0) << out->report.dump();
  size_t in_hole = 0;
  for (size_t g = 0; g < out->added.size(); ++g) {
    const Eigen::Vector3f p(&out->added.positions[3 * g]);
    in_hole += Eigen::Vector2f(p.x(), p.y()).norm() < 0.08f - 0.025f - 0.01f;
  }
  EXPECT_EQ(in_hole, 0u) << out->report.dump();
  EXPECT_GT(out->report["rejected"].value("axis_cap_open_above", 0), 0);
}

// A mug (handle at +x) seen from the front: the body's axis is accepted with a mirror plane
// through it. The plane's turn about the axis rests on the handle alone; the handle lends it no
// images (they would stand centimetres beside the handle when the turn is a few degrees off), so
// nothing is added beyond the body's radius.
TEST(GeometricPrior, AMirrorPlaneThroughTheAxisLendsNoImagesOfTheHandle) {
  ShapeSpec spec;
  spec.kind = ShapeKind::kMug;
  spec.size = {0.05f, 0, 0.1f};
  for (uint64_t seed : {11u, 12u, 13u}) {
    const PartialObject scene = MakePartialObject(MakeShapeMesh(spec, 48), 4000, seed, 100);
    const PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    auto beyond_body = [&](bool skip) {
      GeometricPriorOptions options;
      options.support_cap = false;  // the cap fills the footprint, handle included
      options.mirror_skips_axis_asymmetric = skip;
      auto out = GeometricPrior(options).Complete(fixture.input);
      EXPECT_TRUE(out.ok()) << out.status();
      size_t count = 0;
      for (size_t g = 0; g < out->added.size(); ++g) {
        const Eigen::Vector3f p(&out->added.positions[3 * g]);
        count += Eigen::Vector2f(p.x(), p.y()).norm() > 0.05f + 0.01f;
      }
      return count;
    };
    // Planes a few degrees off the handle's: 9-18 surfels a centimetre or more beyond the body
    // when the handle is mirrored, 0 when not (0-7, revolved and mirrored images of the body's
    // rim, with the handle of before 2026-12-06 that hung into the cavity).
    const size_t mirrored = beyond_body(false), skipped = beyond_body(true);
    EXPECT_GE(mirrored, 8u) << seed;
    EXPECT_LT(2 * skipped, mirrored) << seed;
  }
}

// A mug among neighbours (the synthetic `small` scene of seed 143, half its objects asymmetric,
// never-seen surfels dropped), completed from its true labels: near the table, between its
// neighbours, no view saw the space its handle's lower end revolves into, so the body's axis held
// for that end; revolved, walled and capped, it made a ring about 12 cm across around a mug 7 cm
// wide, and it lifted the body's profile so the rest of the handle left as a neighbour's. As part
// of the handle (the part the axis does not hold for) it lends no images and stays the mug's.
TEST(GeometricPrior, AHandlesLowerEndIsTheHandles) {
  ClutterOptions clutter = *ClutterPreset("small");
  clutter.seed = 143;
  clutter.asymmetric_share = 0.5f;
  absl::StatusOr<ClutterScene> scene = GenerateClutterScene(clutter);
  ASSERT_TRUE(scene.ok()) << scene.status();
  ASSERT_TRUE(DropUnseenSurfels(&*scene).ok());
  const auto mug =
      std::find_if(scene->objects.begin(), scene->objects.end(),
                   [](const SynthObject& o) { return o.shape.kind == ShapeKind::kMug; });
  ASSERT_NE(mug, scene->objects.end());
  const Eigen::AlignedBox3f truth = mug->mesh.Bounds();
  const std::vector<uint32_t> labels(scene->instance_ids.begin(), scene->instance_ids.end());
  auto outside = [&](bool handle_joins_its_part, size_t* foreign) {
    CompletionOptions options;
    options.meshing.size_px = 64;
    options.geometric.handle_joins_its_part = handle_joins_its_part;
    auto done = CompleteObject(scene->cameras, scene->cloud, labels, mug->id, options);
    EXPECT_TRUE(done.ok()) << done.status();
    if (!done.ok()) return size_t{0};
    *foreign = done->prior.foreign.size();
    size_t count = 0;  // completed surfels more than 5 mm outside the true mug's box
    for (size_t g = done->raw.size(); g < done->object.size(); ++g) {
      const Eigen::Vector3f p(&done->object.positions[3 * g]);
      count += truth.exteriorDistance(p) > 0.005f;
    }
    return count;
  };
  size_t foreign_with = 0, foreign_without = 0;
  const size_t with = outside(true, &foreign_with), without = outside(false, &foreign_without);
  EXPECT_LE(with, 5u);
  EXPECT_LE(foreign_with, 10u);  // the handle stays the mug's
  EXPECT_GE(without, 50u);
  EXPECT_GE(foreign_without, 30u);
}

// The sources the accepted hypotheses lend no images (asymmetric), summed over them, by the grid
// alone and with the exact test agreeing; instance 1 of `scene` with a seen-through test.
std::pair<int, int> AsymmetricSources(const PartialObject& scene) {
  PriorFixture fixture(scene);
  EXPECT_TRUE(fixture.ok());
  if (!fixture.ok()) return {0, 0};
  auto seen = SeenThroughTest::Create(scene.cameras, scene.cloud, fixture.input.frame.radius,
                                      SeenThroughOptions{});
  EXPECT_TRUE(seen.ok()) << seen.status();
  if (!seen.ok()) return {0, 0};
  fixture.input.seen_through = &*seen;
  auto count = [&](bool exact) {
    GeometricPriorOptions options;
    options.exact_asymmetry = exact;
    auto out = GeometricPrior(options).Complete(fixture.input);
    EXPECT_TRUE(out.ok()) << out.status();
    return out.ok() ? out->report["asymmetric_sources"].get<int>() : 0;
  };
  return {count(false), count(true)};
}

// A box's n-fold axis has no profile (its radius varies around it), so the rule above goes by the
// body's reach instead: three surfels of a neighbour 9 mm past a box's corner that its label
// surrounds leave the box; unlabelled, they stay (seed 23's box_5 held six of bottle_7's surfels
// by its top corner, extent 10 % too large; RESULTS.md "Neighbours' surfels past a box's corner").
TEST(GeometricPrior, ANeighboursSurfelsPastABoxsCornerAreNotTheBoxs) {
  ShapeSpec spec;
  spec.kind = ShapeKind::kBox;
  spec.size = {0.11f, 0.075f, 0.14f};
  TriangleMesh box = MakeShapeMesh(spec);
  const Eigen::Matrix3d yaw = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).matrix();
  box.Transform({yaw, Eigen::Vector3d::Zero()});
  // Views all round: the corner's image under the 2-fold axis is in space they saw empty.
  PartialObject scene = MakePartialObject(box, 5000, 9, 160);
  // The corner at local (+x, -y), pushed 9 mm further out along its diagonal.
  const Eigen::Vector3f corner = yaw.cast<float>() * Eigen::Vector3f(0.055f, -0.0375f, 0);
  const Eigen::Vector3f out = corner.normalized() * (corner.norm() + 0.009f);
  AppendObjectSurfelsAt({out + Eigen::Vector3f(0, 0, 0.10f), out + Eigen::Vector3f(0, 0, 0.11f),
                         out + Eigen::Vector3f(0, 0, 0.12f)},
                        &scene);
  PriorFixture fixture(scene);
  ASSERT_TRUE(fixture.ok());
  const uint32_t n = static_cast<uint32_t>(fixture.instance.size());
  auto completed = GeometricPrior().Complete(fixture.input);
  ASSERT_TRUE(completed.ok()) << completed.status();
  EXPECT_TRUE(completed->foreign.empty());
  EXPECT_TRUE(completed->report["hypotheses"].dump().find("2-fold axis") != std::string::npos)
      << completed->report["hypotheses"].dump();
  std::vector<uint8_t> labelled(n, 0);
  labelled[n - 1] = labelled[n - 2] = labelled[n - 3] = 1;
  fixture.input.neighbour_labelled = &labelled;
  completed = GeometricPrior().Complete(fixture.input);
  ASSERT_TRUE(completed.ok()) << completed.status();
  EXPECT_EQ(completed->foreign, (std::vector<uint32_t>{n - 3, n - 2, n - 1}));
}

// A thin bottle (3.5 cm radius, as the synthetic scenes' bottles): the free-space grid's voxels
// (4 radii / 64, 8 mm here) straddle its surface where the views graze the silhouette, so by the
// grid alone a quarter of its surfels have revolved or mirrored images in "seen-empty" space
// and lend nothing (an axis so contradicted also fails the 70 % guard of the profile rules). The
// exact test tells the surface from the space beside it; a mug's handle stays asymmetric.
TEST(GeometricPrior, AThinBottlesBodyIsSymmetricWhereViewsGrazeIt) {
  ShapeSpec bottle;
  bottle.kind = ShapeKind::kBottle;
  bottle.size = {0.035f, 0, 0.22f};
  for (uint64_t seed : {31u, 32u, 33u}) {
    // 2439 surfels: 575-624 by the grid, 0-1 with the exact test.
    const auto [grid, exact] =
        AsymmetricSources(MakePartialObject(MakeShapeMesh(bottle, 48), 3000, seed));
    EXPECT_GE(grid, 400) << seed;
    EXPECT_LE(exact, 10) << seed;
  }
  ShapeSpec mug;
  mug.kind = ShapeKind::kMug;
  mug.size = {0.05f, 0, 0.1f};
  for (uint64_t seed : {11u, 12u, 13u}) {
    // 3597 surfels, 308-316 of them the handle's: 318-398 by the grid, 292-367 with the exact
    // test (the axis's sources are the handle; the plane's a few more).
    const auto [grid, exact] =
        AsymmetricSources(MakePartialObject(MakeShapeMesh(mug, 48), 4000, seed, 100));
    EXPECT_GE(exact, 250) << seed;
    EXPECT_GE(exact, grid * 85 / 100) << seed;
  }
}

// An object no symmetry holds for still rests on its support. An L-block seen all round whose
// lowest 2 cm the segmentation gave the background (seed 178's l-block_5 stood 4.5 mm short so):
// no plane or axis passes, yet its walls come down to the support on its own faces; with
// `support_without_symmetry` off the prior abstains.
TEST(GeometricPrior, AnObjectWithoutASymmetryStillRestsOnItsSupport) {
  ShapeSpec spec;
  spec.kind = ShapeKind::kLBlock;
  spec.size = {0.146f, 0.089f, 0.135f};
  const TriangleMesh truth = MakeShapeMesh(spec);
  PartialObject scene = MakePartialObject(truth, 5000, 29, 160);
  for (size_t g = 0; g < scene.labels.size(); ++g) {
    if (scene.labels[g] == 1 && scene.cloud.positions[3 * g + 2] < 0.02f) scene.labels[g] = 0;
  }
  const PriorFixture fixture(scene);
  ASSERT_TRUE(fixture.ok());
  GeometricPriorOptions options;
  options.support_without_symmetry = false;
  auto abstained = GeometricPrior(options).Complete(fixture.input);
  ASSERT_TRUE(abstained.ok()) << abstained.status();
  EXPECT_TRUE(abstained->abstained) << abstained->reason;
  auto rests = GeometricPrior().Complete(fixture.input);
  ASSERT_TRUE(rests.ok()) << rests.status();
  ASSERT_FALSE(rests->abstained) << rests->report.dump();
  EXPECT_EQ(rests->report["hypotheses"].dump().find("accepted"), std::string::npos)
      << rests->report["hypotheses"].dump();
  EXPECT_GT(rests->report["added_by"]["support_walls"].get<int>(), 50) << rests->report.dump();
  auto caster = RayCaster::Create(truth);
  ASSERT_TRUE(caster.ok());
  const GaussianCloud& added = rests->added;
  float lowest = 1;
  size_t off = 0;
  for (size_t g = 0; g < added.size(); ++g) {
    const Eigen::Vector3f p(&added.positions[3 * g]);
    lowest = std::min(lowest, p.z());
    const float* q = &added.rotations[4 * g];
    const Eigen::Vector3f n =
        RotationFromQuaternionWxyz(q[0], q[1], q[2], q[3]).col(2).cast<float>();
    const RayHit a = (*caster)->Cast(p, n), b = (*caster)->Cast(p, -n);
    const float d = std::min(a.hit ? a.distance : 1.0f, b.hit ? b.distance : 1.0f);
    off += d > 0.003f && p.z() > 0.003f;  // cap surfels sit on the support
  }
  EXPECT_LT(lowest, 0.003f);
  EXPECT_LT(off, added.size() / 20) << off << " of " << added.size();
}

}  // namespace
}  // namespace instascene::generation
