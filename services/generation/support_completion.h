// services/generation/support_completion.h: the support part of the geometric prior. Objects rest
// on a support, and the parts next to it are the ones no view sees: the underside always, often
// the lower part of the sides too. Two proposals, both checked by the caller against free space
// and coverage like every other completed surfel:
//   - wall extension: in each azimuth sector around the object, the surfels of the lowest band
//     seen there whose normal is roughly horizontal are repeated straight down, one spacing at a
//     time, to the support (a vertical-wall prior: exact
//     for cylinders, bottles, boxes), or down their own slope where they lean (a sphere's
//     lower band: straight down it added a skirt), along the profile's curvature about a
//     vertical axis of revolution (the tangent ran outside a ball's underside);
//   - cap: surfels on the support plane inside the footprint of the object's lower quarter seen
//     from above (its convex hull, so gaps left in completed walls do not open the bottom),
//     except where the space just above was seen empty (a torus' hole is table, not underside).
//     Under a sphere this overestimates the contact.
// Pure functions, thread-safe.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "services/generation/free_space.h"
#include "services/generation/object_frame.h"

namespace instascene::generation {

// A proposed surfel: position, rotation (columns: tangent u, tangent v, normal), the observed
// surfel lending its appearance, and its log-scales (copied from the source when !has_scale).
struct SurfelCandidate {
  Eigen::Vector3f position = Eigen::Vector3f::Zero();
  Eigen::Matrix3f rotation = Eigen::Matrix3f::Identity();
  uint32_t source = 0;
  bool has_scale = false;
  float log_scale_u = 0, log_scale_v = 0;
};

// `positions` / `rotations` / `sources`: every surfel so far (observed and added), with the
// observed surfel each one takes its appearance from.
// `slope_min_sin` > 0: a surfel whose normal leans more than asin(slope_min_sin) off the
// horizontal where the surface narrows downwards (a sphere's or a bowl's lower band) is repeated
// down its own slope (the steepest descent in its tangent plane, inwards) instead of straight
// down; walls within that of vertical (a bottle's, a box's with noisy normals) and surfaces that
// widen downwards (a shoulder: outwards) still go straight down. Either sign of normal.
// `vertical_axis`: a point on the object's axis of revolution when it is vertical (along
// frame.up); such sloped walls then follow the sphere about the point where the surfel's normal
// line meets the axis (a ball's underside exactly; inwards of the tangent on other shapes), one
// spacing of arc at a time, down to the support or the axis.
std::vector<SurfelCandidate> WallExtension(
    const std::vector<Eigen::Vector3f>& positions, const std::vector<Eigen::Matrix3f>& rotations,
    const std::vector<uint32_t>& sources, const ObjectFrame& frame, float slope_min_sin = 0,
    const std::optional<Eigen::Vector3f>& vertical_axis = std::nullopt);

// `rim_inside_walls`: a cap cell on the footprint's rim (kept where a surfel lies in it) puts its
// surfel no farther out than the wall's surfels in it, not at the cell's centre (up to half a
// cell past the wall).
std::vector<SurfelCandidate> SupportCap(const std::vector<Eigen::Vector3f>& positions,
                                        const std::vector<uint32_t>& sources,
                                        const ObjectFrame& frame, const FreeSpaceGrid& free_space,
                                        bool rim_inside_walls = true);

}  // namespace instascene::generation
