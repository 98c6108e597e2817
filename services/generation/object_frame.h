// services/generation/object_frame.h: the instance / occluder split of a segmented scene and the
// object's local frame (ALGORITHM.md 7.1): centre (AABB centre of the instance's Gaussians), up
// (the support's normal: the scene's dominant up-facing surface, refined by the support right under
// the object; see object_frame.cc), radius (largest distance from the centre),
// and the support plane under the object when the occluders show one. Value types, thread-safe.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "absl/status/statusor.h"
#include "common/geometry/camera.h"
#include "common/splat/gaussian_cloud.h"

namespace instascene::generation {

struct ObjectFrame {
  Eigen::Vector3f center = Eigen::Vector3f::Zero();  // world frame
  Eigen::Vector3f up = Eigen::Vector3f::UnitZ();     // unit, world frame
  float radius = 0;                                  // scene units
  bool has_support = false;
  float support_height = 0;  // support plane: {x : up . x = support_height}
  float bottom_height = 0;   // lowest instance point along up
  float spacing = 0;         // median nearest-neighbour distance of the instance's Gaussians

  // Orthonormal basis (x, y, up) of the frame; x is any direction orthogonal to up.
  Eigen::Matrix3f Basis() const;
};

struct InstanceSplit {
  std::vector<uint32_t> instance;   // Gaussians labelled with the instance id, scene order
  std::vector<uint32_t> occluders;  // every other Gaussian
  size_t outliers = 0;              // instance Gaussians moved to the occluders (see below)
};

// Splits by label. FailedPrecondition when the instance has fewer than `min_gaussians` members
// (empty or degenerate instance): the message names the instance.
absl::StatusOr<InstanceSplit> SplitInstance(const std::vector<uint32_t>& labels, uint32_t id,
                                            size_t min_gaussians);

// The connected components RemoveStrayGaussians moved to the occluders (cloud indices).
using StrayComponents = std::vector<std::vector<uint32_t>>;

// Segmentations carry stray Gaussians (floaters, a few surfels of the support or a neighbour);
// completing them would mirror and revolve them into rings of garbage. Keeps the connected
// components of the instance (link: `link_spacings` median spacings) holding at least
// `min_share` of the largest one's Gaussians; the rest become occluders (returned).
StrayComponents RemoveStrayGaussians(const GaussianCloud& cloud, InstanceSplit* split,
                                     float link_spacings = 4.0f, float min_share = 0.2f);

// A sharp tip is sampled sparsely (surfels spread by area leave a cone's last ones apart), so
// the stray removal cuts it off though it continues the object. A removed component of at most
// `max_surfels` returns to the instance when its lowest surfel stands above the body's highest
// one by at most `max_gap_spacings` frame spacings and every surfel of it stands within the
// outline of the body's top: horizontally within the top band's (the body's surfels within one
// spacing of its top) farthest reach from the band's centre, plus one spacing. A neighbour's or the
// support's surfels stand beside or below the object, not over its top. Returns how many surfels
// returned; the caller recomputes the frame.
size_t ReturnTips(const GaussianCloud& cloud, const ObjectFrame& frame,
                  const StrayComponents& strays, InstanceSplit* split, size_t max_surfels = 8,
                  float max_gap_spacings = 6.0f);

// Surfels of the support labelled as the instance (the table's small surfels around an object's
// base): instance surfels within `band_spacings` frame spacings of the support plane whose
// normal is within 15 degrees of up become occluders (counted in `outliers`). An object's own
// underside never shows, so nothing of it is lost; left in, they widened the base and the
// support cap over them by a centimetre. Returns how many moved; the caller recomputes the frame.
size_t RemoveSupportSurfels(const GaussianCloud& cloud, const ObjectFrame& frame,
                            InstanceSplit* split, float band_spacings = 0.5f);

// Per instance surfel (in `split.instance` order): whether at least half of its `k` nearest
// surfels outside the instance, counting those within `reach_spacings` frame spacings, carry one
// other instance's label (background, label 0, and the instance's own label on the surfels that
// left it never count): a touching neighbour's surfel that the segmentation
// gave this object, or the object's own surfel at the contact. Alone it cannot tell the two apart;
// the geometric prior uses it only for surfels beyond the body's profile (geometric_prior.h).
std::vector<uint8_t> NeighbourLabelled(const GaussianCloud& cloud,
                                       const std::vector<uint32_t>& labels,
                                       const InstanceSplit& split, const ObjectFrame& frame,
                                       int k = 8, float reach_spacings = 6.0f);

// The frame of `split.instance` in `cloud` (surfels). Support: occluder surfels facing up within
// the object's footprint, just below its lowest point (median of their heights).
ObjectFrame ComputeObjectFrame(const GaussianCloud& cloud, const InstanceSplit& split,
                               const std::vector<PinholeCamera>& cameras);

}  // namespace instascene::generation
