// services/generation/refinement_views.h: the supervision of the joint refinement (ALGORITHM.md
// 7.9) for one object.
// - Generated views: the ring cameras with the completed object's own renders before refinement
//   (white background, mask = alpha > 0.5). With the geometric prior these renders are the
//   prior's "generated images": they hold the completed shape where no real view constrains it,
//   while the real views correct the appearance; a prior that returns images (a diffusion
//   backend) supplies its own for the unknown views.
// - Real views: each training view cropped to the completed object's footprint (alpha > 0.5,
//   margin 4 px) and binned by an integer factor to at most `max_side` px (exact area averaging;
//   the camera is cropped and scaled to match). The object is rendered in situ: the view's
//   context is every other scene surfel the crop sees, so the image is explained everywhere and
//   the loss covers the whole crop: observed surfels stay where the capture put them, and
//   completed surfels that show where the image shows something else are corrected. A view
//   where fewer than `min_pixels` pixels of the observed instance are seen unoccluded (its own
//   alpha > 0.5 and median depth within 3 surfel spacings + 1 % of the scene's) is skipped.
// Stateless, thread-safe.
#pragma once

#include <optional>
#include <vector>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/scene/image_io.h"
#include "common/splat/gaussian_cloud.h"
#include "services/generation/object_frame.h"
#include "services/generation/prior.h"
#include "services/generation/refinement.h"

namespace instascene::generation {

// One generated view per ring camera; `images` (the prior's, may be empty) replace the object's
// own render at the cameras they were made for.
absl::StatusOr<std::vector<RefinementView>> GeneratedRefinementViews(
    const GaussianCloud& object, const std::vector<PinholeCamera>& ring, const ObjectFrame& frame,
    const std::vector<ViewImages>& images, int num_threads);

// The real view's crop, or nullopt when fewer than `min_pixels` pixels of the instance are seen
// unoccluded. InvalidArgument when the image does not match the camera.
// `instance` are the observed instance's indices into `scene`, `object` the completed object.
absl::StatusOr<std::optional<RefinementView>> RealRefinementView(
    const PinholeCamera& camera, const Image& image, const GaussianCloud& object,
    const GaussianCloud& scene, const std::vector<uint32_t>& instance, const ObjectFrame& frame,
    int max_side, int num_threads, int min_pixels = 64);

}  // namespace instascene::generation
