// services/generation/prior.h: the completion prior interface (GENERATION.md step 4). A prior gets
// the observed instance, its frame, the space real views saw empty and the ring's known (condition)
// and unknown (target) views with their condition images; it returns completed surfels and/or
// images for the target views. The built-in `geometric` prior (geometric_prior.h) returns surfels;
// a `diffusion` backend returns RGB, depth and mask per target, which refinement back-projects.
// Implementations must be thread-compatible (one Complete at a time per object).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "common/core/cancel.h"
#include "common/geometry/camera.h"
#include "common/splat/gaussian_cloud.h"
#include "services/generation/free_space.h"
#include "services/generation/object_frame.h"
#include "services/generation/seen_through.h"

namespace instascene::generation {
namespace diffusion {
class LatentCodec;  // diffusion/latent_codec.h
}

// One rendered view of the instance alone (white background), ALGORITHM.md 7.4.
struct ViewImages {
  PinholeCamera camera;
  std::vector<float> rgb;     // HxWx3 in [0, 1]
  std::vector<float> depth;   // HxW median depth, 0 where the mask is empty
  std::vector<float> alpha;   // HxW
  std::vector<uint8_t> mask;  // HxW, alpha > 0.5
};

struct PriorInput {
  const GaussianCloud* instance = nullptr;  // observed surfels, scene frame (not owned)
  ObjectFrame frame;
  const FreeSpaceGrid* free_space = nullptr;  // not owned
  // The exact free-space test (did a real view see through a point?); may be null.
  const SeenThroughTest* seen_through = nullptr;  // not owned
  // Per instance surfel, whether a touching neighbour's label surrounds it
  // (object_frame.h NeighbourLabelled); may be null.
  const std::vector<uint8_t>* neighbour_labelled = nullptr;  // not owned
  std::vector<ViewImages> conditions;                        // known ring views
  std::vector<PinholeCamera> targets;                        // unknown ring views
  uint64_t seed = 1;
  const CancelFlag* cancel = nullptr;
};

struct PriorOutput {
  GaussianCloud added;  // completed surfels (same SH degree as the instance), may be empty
  std::vector<ViewImages> generated;  // images at the target views, or empty
  bool abstained = false;             // nothing added: the object stays a closed crop
  std::string reason;                 // why it abstained, or what it did
  nlohmann::json report = nlohmann::json::object();  // prior-specific details for the manifest
  // Instance surfels (indices into PriorInput::instance) the prior found not to be the object's
  // (a neighbour's surfels the segmentation gave it): the caller moves them to the occluders.
  std::vector<uint32_t> foreign;
  // An accepted axis of revolution (continuous, not n-fold) shaped the completion: it revolved
  // the observed part all round, and what is inside (a cup's cavity) is the axis's (the meshing
  // does not fill it, MeshingOptions::enclose_hull). A box's n-fold axis leaves the inside to the
  // hull: a face seen only edge-on stays a gap its copies do not fill, and the box meshed hollow.
  bool revolution_axis = false;
  // An accepted n-fold axis (a box's) shaped the completion: its copies stand on every side of
  // the object, whose sides the meshing keeps within them (MeshObject's `surfels_all_round`).
  bool order_axis = false;
};

class CompletionPrior {
 public:
  virtual ~CompletionPrior() = default;
  virtual std::string name() const = 0;
  virtual absl::StatusOr<PriorOutput> Complete(const PriorInput& input) const = 0;
  // Whether Complete reads PriorInput::seen_through (the caller builds it only then: a second
  // ray-casting structure over the whole scene).
  virtual bool UsesSeenThrough() const { return false; }
};

// The diffusion prior's two open choices of ALGORITHM.md 7.7, as settings (defaults and why:
// diffusion/diffusion_prior.h).
struct DiffusionSettings {
  double replace_fraction = 1.0;  // replace known pixels during this share of the steps (from t=T)
  std::string warp = "latent";    // "latent": warp on the latent grid; "pixel": at the ring's
                                  // resolution, then encode (a cell is known by majority)
  // Generate only inside the unseen-region estimate (ALGORITHM.md 7.8) or on the object; pixels
  // that look through space real views saw empty are pinned to the background.
  bool unseen_mask = true;
  // The image encoder / decoder around the denoiser (a site's VAE); null = the identity.
  std::shared_ptr<const diffusion::LatentCodec> codec;
};

struct GeometricPriorOptions;  // geometric_prior.h

// The prior named `name`: "geometric" (with `geometric`'s options; nullptr = the defaults),
// "none", or "diffusion" (which needs `denoiser`, a Denoiser service as grpc://HOST:PORT;
// diffusion/diffusion_prior.h). InvalidArgument for an unknown name or a missing / malformed
// denoiser.
absl::StatusOr<std::unique_ptr<CompletionPrior>> MakePrior(
    const std::string& name, const std::string& denoiser = "",
    const DiffusionSettings& diffusion = {}, const GeometricPriorOptions* geometric = nullptr);

}  // namespace instascene::generation
