// services/generation/testing/partial_objects.h: the test scenes of the generation stage's tests
// (linked into generation_test): one object on a table seen from its front half only, the
// shapes they use, and the prior's and the symmetry detector's inputs built from them. Helpers
// report setup failures through gtest's EXPECT macros. Deterministic from their seeds.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "common/geometry/camera.h"
#include "common/geometry/triangle_mesh.h"
#include "common/mesh/ray_caster.h"
#include "common/splat/gaussian_cloud.h"
#include "services/generation/free_space.h"
#include "services/generation/geometric_prior.h"
#include "services/generation/object_frame.h"
#include "services/generation/symmetry.h"

namespace instascene::generation::testing {

inline constexpr double kPi = 3.14159265358979323846;

// One object on a table (z = 0 plane), seen by cameras on the front half only (azimuth -70..70 deg
// around +x): the back and the underside are never seen. Surfels facing away from every camera are
// dropped (the object is convex or nearly so, so that is its visible part).
struct PartialObject {
  GaussianCloud cloud;           // table + observed object surfels
  std::vector<uint32_t> labels;  // 1 = object
  std::vector<PinholeCamera> cameras;
};

PartialObject MakePartialObject(const TriangleMesh& object_mesh, size_t count, uint64_t seed,
                                double front_half_angle_deg = 70);

// A bottle of radius 5 cm and height 25 cm (the synthetic generator's shape, 48 segments).
TriangleMesh Bottle();

// An L of two boxes of different heights: no vertical mirror plane, no axis.
TriangleMesh LBlock();

// The synthetic generator's L-block (a tall bar, a lower arm at one end) with its arm towards
// views that cover only 70 degrees in front of it: the space behind the bar is seen by none.
PartialObject LBlockArmTowardsTheViews();

// The free space of a test scene around `frame`, carved against all its surfels (the caster is
// kept beside the grid, which points at it).
struct SceneFreeSpace {
  std::unique_ptr<RayCaster> caster;
  std::optional<FreeSpaceGrid> grid;
};

SceneFreeSpace CarveScene(const PartialObject& scene, const ObjectFrame& frame);

// The prior's input for instance 1 of a test scene: its frame, surfels and carved free space
// (no seen-through test: the grid alone).
struct PriorFixture {
  explicit PriorFixture(const PartialObject& scene);
  PriorFixture(const PriorFixture&) = delete;
  PriorFixture& operator=(const PriorFixture&) = delete;
  bool ok() const { return input.free_space != nullptr; }
  SceneFreeSpace space;
  GaussianCloud instance;
  PriorInput input;
};

// Copies of the scene's last surfels (the object's), moved to `targets` and labelled as the
// object: a neighbour's surfels the segmentation gave it. They come last in the instance.
void AppendObjectSurfelsAt(const std::vector<Eigen::Vector3f>& targets, PartialObject* scene);

// The object frame and the symmetry hypotheses of instance 1 of a test scene.
struct Detected {
  ObjectFrame frame;
  std::vector<SymmetryHypothesis> hypotheses;
};

// With the observed surface the prior builds (no seen-through test) for the alignment cost.
Detected Detect(const PartialObject& scene, const SymmetryOptions& options = {});

// Three surfels of a neighbour, 1 cm beside the base of `Bottle()`.
extern const std::vector<Eigen::Vector3f> kStraysBesideTheBase;

// A partly seen bottle (radius 5 cm) inside a tray's rim that hides the space around its base
// from every view, and surfels of a neighbour at `targets` that the segmentation gave it: the last
// ones of the instance.
PartialObject BottleWithANeighboursStrays(
    uint64_t seed, size_t count = 4000,
    const std::vector<Eigen::Vector3f>& targets = kStraysBesideTheBase);

}  // namespace instascene::generation::testing
