// GeometricPrior: a touching neighbour's surfels that the segmentation gave the object (issue 12's
// errors downstream) are not revolved, mirrored or kept as the object's.
#include "services/generation/geometric_prior.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

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

// A partly seen bottle whose segmentation also holds three surfels of a neighbour, 1 cm
// beside its base, inside a tray's rim that hides the space around the base from every view
// (their images are not in seen-empty space, so the axis holds for them): revolved and mirrored
// they would ring the bottle's base. They lie beyond the body's profile at their height, lend
// the axis and the plane through it nothing, and are reported as not the bottle's (foreign).
TEST(GeometricPrior, ANeighboursSurfelsBesideTheBaseAreNotRevolvedIntoARing) {
  for (uint64_t seed : {21u, 22u, 23u}) {
    const PartialObject scene = BottleWithANeighboursStrays(seed);
    const float bottle_radius = 0.05f;
    const PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    auto ringed = [&](bool skip) {
      GeometricPriorOptions options;
      options.support_cap = false;  // the cap fills the footprint under the strays too
      options.skip_beyond_axis_profile = skip;
      auto out = GeometricPrior(options).Complete(fixture.input);
      EXPECT_TRUE(out.ok()) << out.status();
      size_t count = 0;
      for (size_t g = 0; g < out->added.size(); ++g) {
        const Eigen::Vector3f p(&out->added.positions[3 * g]);
        count += p.z() < 0.04f && Eigen::Vector2f(p.x(), p.y()).norm() > bottle_radius + 0.008f;
      }
      return count;
    };
    // 34-36 surfels of a ring beyond the base with the strays revolved and mirrored, 0 without.
    const size_t revolved = ringed(false), skipped = ringed(true);
    EXPECT_GE(revolved, 20u) << seed;
    EXPECT_LE(skipped, 2u) << seed;
    // And the strays, the last three of the instance, are found not to be the bottle's.
    auto out = GeometricPrior().Complete(fixture.input);
    ASSERT_TRUE(out.ok()) << out.status();
    const uint32_t n = static_cast<uint32_t>(fixture.instance.size());
    EXPECT_EQ(out->foreign, (std::vector<uint32_t>{n - 3, n - 2, n - 1})) << seed;
    EXPECT_EQ(out->report["foreign_observed"], 3) << seed;
  }
}

// Strays beside the base where the views saw the space around them (no tray's rim): their
// images lie in seen-empty space, as a handle's do, so the axis lends them nothing and keeps them;
// where a touching neighbour's label surrounds them, they are not the bottle's.
TEST(GeometricPrior, StraysANeighboursLabelSurroundsAreNotTheObjects) {
  // Seeds whose fitted axis holds for at least 70 % of the bottle (on others it is offset and
  // claims nothing beyond its profile: the guard of geometric_prior.h).
  for (uint64_t seed : {3u, 22u, 23u}) {
    PartialObject scene = MakePartialObject(Bottle(), 4000, seed);
    AppendObjectSurfelsAt(
        {Eigen::Vector3f(0.061f, 0.004f, 0.012f), Eigen::Vector3f(0.060f, -0.006f, 0.018f),
         Eigen::Vector3f(0.062f, 0.010f, 0.024f)},
        &scene);
    PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    const uint32_t n = static_cast<uint32_t>(fixture.instance.size());
    // Each stray stands alone (1 cm apart), which `ALoneSurfelBesideTheBodyIsNoHandle` judges;
    // counted as parts of a handle here, the label alone decides.
    GeometricPriorOptions options;
    options.min_handle_surfels = 0;
    options.min_handle_share = 0;
    auto out = GeometricPrior(options).Complete(fixture.input);
    ASSERT_TRUE(out.ok()) << out.status();
    EXPECT_TRUE(out->foreign.empty()) << seed;  // a handle's case: kept
    std::vector<uint8_t> labelled(n, 0);
    labelled[n - 1] = labelled[n - 2] = labelled[n - 3] = 1;
    fixture.input.neighbour_labelled = &labelled;
    out = GeometricPrior(options).Complete(fixture.input);
    ASSERT_TRUE(out.ok()) << out.status();
    EXPECT_EQ(out->foreign, (std::vector<uint32_t>{n - 3, n - 2, n - 1})) << seed;
  }
}

// One surfel of a neighbour half a spacing beyond the bottle (radius 5 cm) near its base, inside
// the tray's rim (the axis holds for it) and surrounded by the neighbour's label: within the
// profile's one-spacing tolerance that every other surfel gets, so it stayed the bottle's and was
// revolved into a band half a spacing wide around it (seed 141's bottle_1, its extent 6 % too
// large). A surfel a neighbour's label surrounds gets no tolerance: it leaves the bottle.
TEST(GeometricPrior, ANeighboursSurfelWithinTheProfilesToleranceIsNotTheObjects) {
  for (uint64_t seed : {21u, 22u, 23u}) {
    float spacing = 0;
    {
      const PriorFixture plain(MakePartialObject(Bottle(), 4000, seed));
      ASSERT_TRUE(plain.ok());
      spacing = plain.input.frame.spacing;
    }
    const PartialObject scene = BottleWithANeighboursStrays(
        seed, 4000, {Eigen::Vector3f(0.05f + 0.5f * spacing, 0.0f, 0.018f)});
    PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    const uint32_t n = static_cast<uint32_t>(fixture.instance.size());
    std::vector<uint8_t> labelled(n, 0);
    labelled[n - 1] = 1;
    fixture.input.neighbour_labelled = &labelled;
    auto foreign = [&](float tolerance) {
      GeometricPriorOptions options;
      options.neighbour_profile_spacings = tolerance;
      auto out = GeometricPrior(options).Complete(fixture.input);
      EXPECT_TRUE(out.ok()) << out.status();
      return out.ok() ? out->foreign : std::vector<uint32_t>{};
    };
    EXPECT_EQ(foreign(0.0f), std::vector<uint32_t>{n - 1}) << seed;
    EXPECT_TRUE(foreign(1.0f).empty()) << seed;  // the tolerance every other surfel gets
  }
}

// Many of a neighbour's surfels at one height (30 at the contact, 6-7 mm beside the bottle,
// inside the tray's rim: the axis holds for them): a tenth of the profile's window, they lift its
// percentile over themselves and all stay (seed 53's bottle_2 kept two of six that way, its
// extent 8 % too large). A neighbour's label surrounds them, so they are not the profile's
// witnesses: all leave the bottle.
TEST(GeometricPrior, TheProfileIsTheBodysNotTheNeighboursItJudges) {
  std::vector<Eigen::Vector3f> crowd;
  for (int k = 0; k < 30; ++k) {
    const float angle = 0.015f * static_cast<float>(k % 10 - 5);
    const float radius = 0.056f + 0.0005f * static_cast<float>(k % 3);
    crowd.emplace_back(radius * std::cos(angle), radius * std::sin(angle),
                       0.014f + 0.003f * static_cast<float>(k / 10));
  }
  for (uint64_t seed : {21u, 22u, 23u}) {
    const PartialObject scene = BottleWithANeighboursStrays(seed, 4000, crowd);
    PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    const uint32_t n = static_cast<uint32_t>(fixture.instance.size());
    std::vector<uint8_t> labelled(n, 0);
    for (uint32_t k = 0; k < crowd.size(); ++k) labelled[n - 1 - k] = 1;
    fixture.input.neighbour_labelled = &labelled;
    auto foreign_crowd = [&](bool skip) {
      GeometricPriorOptions options;
      options.profile_skips_neighbour_labelled = skip;
      options.neighbour_profile_spacings = 1.0f;  // this rule alone, with the old tolerance
      auto out = GeometricPrior(options).Complete(fixture.input);
      EXPECT_TRUE(out.ok()) << out.status();
      return out.ok() ? std::count_if(out->foreign.begin(), out->foreign.end(),
                                      [&](uint32_t g) { return g + crowd.size() >= n; })
                      : 0;
    };
    EXPECT_EQ(foreign_crowd(true), 30) << seed;
    EXPECT_LT(foreign_crowd(false), 15) << seed;
  }
}

// A touching neighbour's patch at the contact (a 5 x 5 sheet of its surfels, 2.5 mm apart, 8-9
// mm beside a partly seen bottle, where the views saw the space around it): a neighbour's label
// surrounds only the patch's rim, the instance's own label its inner part. The rim leaves the
// bottle by the neighbour-label rule; the inner part, beyond the profile and joined to the rim,
// leaves with it (seed 51's bottle_2 kept 12 of a neighbour's surfels that way, its extent 13 %
// too large; RESULTS.md "Neighbours' surfels at the contact"); without the patch rule it stays.
TEST(GeometricPrior, ANeighboursPatchAtTheContactLeavesWhole) {
  for (uint64_t seed : {3u, 22u, 23u}) {
    PartialObject scene = MakePartialObject(Bottle(), 4000, seed);
    std::vector<Eigen::Vector3f> patch;
    for (int i = -2; i <= 2; ++i) {
      for (int j = -2; j <= 2; ++j) {
        const float y = 0.0025f * static_cast<float>(i);
        patch.emplace_back(0.058f + 10.0f * y * y, y, 0.10f + 0.0025f * static_cast<float>(j));
      }
    }
    AppendObjectSurfelsAt(patch, &scene);
    PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    const uint32_t n = static_cast<uint32_t>(fixture.instance.size());
    const uint32_t first = n - static_cast<uint32_t>(patch.size());
    std::vector<uint8_t> labelled(n, 0);
    std::vector<uint32_t> rim, whole;
    for (uint32_t k = 0; k < patch.size(); ++k) {
      const bool on_rim = k / 5 == 0 || k / 5 == 4 || k % 5 == 0 || k % 5 == 4;
      labelled[first + k] = on_rim;
      if (on_rim) rim.push_back(first + k);
      whole.push_back(first + k);
    }
    fixture.input.neighbour_labelled = &labelled;
    GeometricPriorOptions options;
    auto out = GeometricPrior(options).Complete(fixture.input);
    ASSERT_TRUE(out.ok()) << out.status();
    EXPECT_EQ(out->foreign, whole) << seed;
    options.drop_patches_beyond_axis_profile = false;
    out = GeometricPrior(options).Complete(fixture.input);
    ASSERT_TRUE(out.ok()) << out.status();
    EXPECT_EQ(out->foreign, rim) << seed;
  }
}

// One surfel of a neighbour 1 cm beside a bottle's foot, among that neighbour's surfels the
// segmentation left unlabelled (so no label says whose it is), where views saw the space around
// the bottle: the bottle's axis does not hold for it (its images lie in seen-empty space) and it
// stands clear of the body, as a handle would. Alone it is no handle: it leaves the bottle and
// lends no images; counted as a handle (min_handle_surfels 0) it stays. A real handle stays the
// mug's (`AHandlesLowerEndIsTheHandles`).
TEST(GeometricPrior, ALoneSurfelBesideTheBodyIsNoHandle) {
  // Seeds whose fitted axis holds for at least 70 % of the bottle (as in the test above).
  for (uint64_t seed : {22u, 23u}) {
    PartialObject scene = MakePartialObject(Bottle(), 4000, seed);
    AppendObjectSurfelsAt({{0.061f, 0.004f, 0.012f}}, &scene);
    const PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    const uint32_t stray = static_cast<uint32_t>(fixture.instance.size()) - 1;
    auto foreign = [&](int min_handle_surfels) {
      GeometricPriorOptions options;
      options.min_handle_surfels = min_handle_surfels;
      options.min_handle_share = 0;  // the count alone (the share is the next test's)
      auto out = GeometricPrior(options).Complete(fixture.input);
      EXPECT_TRUE(out.ok()) << out.status();
      return out.ok() ? out->foreign : std::vector<uint32_t>{};
    };
    EXPECT_EQ(foreign(3), std::vector<uint32_t>{stray}) << seed;
    EXPECT_TRUE(foreign(0).empty()) << seed;
  }
}

// A patch of a neighbour, 36 surfels 1 cm beside a bottle where views saw the space around it
// (seed 177's cylinder_4 held 23 of bottle_1's surfels so, 9 mm wide): more than a stray, but
// no handle: a part under 2.5 % of the object's surfels leaves it (handles are 4-12 % of the
// synthetic mugs'); counted as a handle (min_handle_share 0) it stays.
TEST(GeometricPrior, ANeighboursPatchOfAFewDozenSurfelsIsNoHandle) {
  std::vector<Eigen::Vector3f> patch;
  for (int i = 0; i < 6; ++i) {
    for (int k = 0; k < 6; ++k)
      patch.emplace_back(0.062f, -0.008f + 0.003f * i, 0.05f + 0.003f * k);
  }
  for (uint64_t seed : {22u, 23u}) {
    PartialObject scene = MakePartialObject(Bottle(), 4000, seed);
    AppendObjectSurfelsAt(patch, &scene);
    const PriorFixture fixture(scene);
    ASSERT_TRUE(fixture.ok());
    const uint32_t n = static_cast<uint32_t>(fixture.instance.size());
    std::vector<uint32_t> appended;
    for (uint32_t g = n - static_cast<uint32_t>(patch.size()); g < n; ++g) appended.push_back(g);
    auto foreign = [&](float min_handle_share) {
      GeometricPriorOptions options;
      options.min_handle_share = min_handle_share;
      auto out = GeometricPrior(options).Complete(fixture.input);
      EXPECT_TRUE(out.ok()) << out.status();
      return out.ok() ? out->foreign : std::vector<uint32_t>{};
    };
    EXPECT_EQ(foreign(GeometricPriorOptions{}.min_handle_share), appended) << seed << " of " << n;
    EXPECT_TRUE(foreign(0).empty()) << seed;
  }
}

}  // namespace
}  // namespace instascene::generation
