// services/generation/geometric_prior.h: the completion prior that needs no weights (GENERATION.md
// step 4, `geometric`). It detects vertical symmetry planes and axes of the observed part
// (symmetry.h), adds the mirrored / revolved images of observed surfels, extends walls down to the
// support and closes the underside on it (support_completion.h); a candidate is added only where
// space is neither observed-empty (FreeSpaceGrid) nor already covered by a surfel, with appearance
// (DC colour, opacity, scales) taken from its source surfel. The support part holds for objects
// no hypothesis holds for too; when nothing is added it abstains and says so. Thread-safe
// (stateless apart from options).
#pragma once

#include "services/generation/observed_surface.h"
#include "services/generation/prior.h"
#include "services/generation/support_completion.h"
#include "services/generation/symmetry.h"

namespace instascene::generation {

struct GeometricPriorOptions {
  SymmetryOptions symmetry;
  float cover_spacings = 1.5f;  // a candidate within this many spacings of a surfel is redundant
  bool support_cap = true;      // close the underside on the support plane
  bool axis_cap =
      true;  // close the lowest ring of an accepted rotation axis (a sphere's underside)
  // Also refuse a candidate some real view saw through at its pixel resolution
  // (PriorInput::seen_through, seen_through.h). Measured in RESULTS.md ("Free-space violations").
  bool exact_free_space = true;
  // A surfel's image counts as contradicting a hypothesis only where the exact test (one real
  // view through the 1-sigma discs) agrees with the grid that the space is seen empty.
  bool exact_asymmetry = true;
  // A candidate is refused in a voxel this many real views saw empty (one view suffices: space a
  // single view saw through is free; symmetry scoring keeps the grid's min_views). Measured in
  // RESULTS.md ("Free-space violations").
  int candidate_free_views = 1;
  float max_support_gap_radii = 1.0f;  // no support completion when it is farther below
  // An object no symmetry hypothesis holds for still rests on its support: its walls are
  // extended down to it and its underside closed on it (the prior abstains only where that adds
  // nothing too). Measured in RESULTS.md ("The support without a symmetry").
  bool support_without_symmetry = true;
  // The cap's rim cells put their surfels no farther out than the walls' surfels in them
  // (support_completion.h). Measured in RESULTS.md ("The cap's rim inside the walls").
  bool cap_rim_inside_walls = true;
  // Support walls: a lowest-band surfel more than asin(this) (15 degrees) off vertical on a
  // surface that narrows downwards is extended down its own slope, inwards, not straight down
  // (support_completion.h; 0 = always straight down). Measured in RESULTS.md ("Support walls
  // down their slope").
  float wall_slope_min_sin = 0.26f;
  // About an accepted vertical axis of revolution those sloped walls follow the sphere about the
  // point where the surfel's normal meets the axis, not its tangent (which ran outside a ball's
  // underside). Measured in RESULTS.md ("Support walls along the profile's curvature").
  bool walls_follow_curvature = true;
  // A mirror plane that contains an accepted revolution axis is oriented about that axis only by
  // the parts the axis does not hold for (a mug's handle), weakly: a plane a few degrees off
  // mirrors the handle centimetres beside itself. Such a plane lends no images of those parts.
  // Measured in RESULTS.md ("Free-space violations: mirrored handles").
  bool mirror_skips_axis_asymmetric = true;
  // An accepted continuous revolution axis (not an n-fold one) that holds for at least 70 % of
  // the surfels lends no images of the surfels it holds for that stand more than a spacing
  // beyond the body's profile at their height (the 90th percentile of the radii around that
  // height, over at least 40 surfels), nor does a mirror plane containing it: a few surfels of a
  // neighbour that the segmentation gave the object would otherwise come back as a ring around
  // it. Measured in RESULTS.md ("Neighbours' surfels revolved").
  bool skip_beyond_axis_profile = true;
  // The profile leaves out the surfels a touching neighbour's label surrounds
  // (PriorInput::neighbour_labelled): they are what it judges. Measured in RESULTS.md
  // ("Neighbours' surfels at the contact").
  bool profile_skips_neighbour_labelled = true;
  // How far beyond the profile's percentile such a surfel may stand and still be judged the
  // object's, in spacings (every other surfel: one). Revolved, one that is a neighbour's rings the
  // object with a wider band; dropped, one that is the object's costs nothing, the axis revolves
  // the others at its height into its place. Measured in RESULTS.md ("Neighbours' surfels within
  // the profile's tolerance").
  float neighbour_profile_spacings = 0.0f;
  // ... and such surfels are not the object's: they leave it for the occluders (reported as
  // PriorOutput::foreign) and hold out no support wall or cap. Measured in RESULTS.md
  // ("Neighbours' surfels revolved").
  bool drop_beyond_axis_profile = true;
  // Surfels such an axis does not hold for (their images lie in seen-empty space, as a handle's
  // do) beyond its profile are not the object's either where a touching neighbour's label
  // surrounds them (PriorInput::neighbour_labelled): they leave it too; about an n-fold axis
  // (a box), those beyond the body's reach, its corners.
  bool drop_neighbours_beyond_axis_profile = true;
  // ... and the surfels beyond the profile that such flagged surfels reach through each other
  // (within three spacings): the inner part of a neighbour's patch at the contact, where the
  // instance's own label surrounds them. Measured in RESULTS.md ("Neighbours' surfels at the
  // contact").
  bool drop_patches_beyond_axis_profile = true;
  // About an accepted axis of revolution a handle is one part: the surfels more than three
  // spacings beyond the body's median radius at their height that join the part the axis does
  // not hold for (within three spacings, repeatedly) are that part's too: no images, no witness
  // of the profile, never a neighbour's (a part reaching a surfel a touching neighbour's label
  // surrounds is that neighbour's patch and is left to the rules above). Near the support no view
  // saw the space the handle's lower end would revolve into, so the axis held for it for lack of
  // evidence, revolved it into a ring and lifted the body's profile with it. Measured in
  // RESULTS.md ("A handle's lower end is the handle's").
  bool handle_joins_its_part = true;
  // A handle is many surfels: a part (as above) of fewer than this many, clear of every other
  // instance's label, is not a handle but a neighbour's stray that the segmentation gave the
  // object among the neighbour's unlabelled surfels (where the label test cannot see it): it
  // leaves the object (PriorOutput::foreign). 0 = every part is a handle. Measured in RESULTS.md
  // ("A handle is more than a stray").
  int min_handle_surfels = 3;
  // ... nor is a part smaller than this share of the instance's surfels (a neighbour's patch of a
  // few dozen where the label test cannot see it; the synthetic mugs' handles are 4-12 % of their
  // mug's surfels). Measured in RESULTS.md ("A handle is a share of its object").
  float min_handle_share = 0.025f;
  // Refuse a candidate standing off the observed surface beside it (observed_surface.h).
  // Measured in RESULTS.md ("Free-space violations: candidates off the observed surface").
  ObservedSurfaceOptions observed_surface;
};

class GeometricPrior final : public CompletionPrior {
 public:
  explicit GeometricPrior(GeometricPriorOptions options = {}) : options_(options) {}
  std::string name() const override { return "geometric"; }
  absl::StatusOr<PriorOutput> Complete(const PriorInput& input) const override;
  bool UsesSeenThrough() const override { return options_.exact_free_space; }

 private:
  GeometricPriorOptions options_;
};

// The prior that adds nothing (the closed crop).
class NoPrior final : public CompletionPrior {
 public:
  std::string name() const override { return "none"; }
  absl::StatusOr<PriorOutput> Complete(const PriorInput& input) const override;
};

}  // namespace instascene::generation
