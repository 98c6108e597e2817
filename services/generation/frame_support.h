// services/generation/frame_support.h: the parts of an object's frame (object_frame.h) read from
// the scene around the object: its up, from the normals of the support surfaces, and the height
// of the support it stands on.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "common/geometry/camera.h"
#include "common/splat/gaussian_cloud.h"
#include "services/generation/object_frame.h"

namespace instascene::generation {

// The cameras' mean up (OpenCV axes); +z without cameras. Only rough: a capture that looks down
// tilts it towards the scene's back.
Eigen::Vector3f MeanCameraUp(const std::vector<PinholeCamera>& cameras);

// The median of `values` (0 when empty).
float Median(std::vector<float> values);

// A surfel's normal (its rotation's third column).
Eigen::Vector3f SurfelNormal(const GaussianCloud& cloud, uint32_t g);

// The object's up, refined from `rough_up` in two steps. (a) The scene's: the mode of the normals
// of every occluder surfel facing roughly up (within 35 degrees; at most 20000 of them, a fixed
// stride): the support most of the scene rests on. (b) The object's: the mode of the normals of
// occluder surfels near and below the object (`points`, centred at `center`) within 15 degrees
// of the scene's up: its own support, robust against neighbouring objects' tilted surfaces.
// `horizontal_radius` receives the object's horizontal radius about the scene's up.
Eigen::Vector3f EstimateUp(const GaussianCloud& cloud, const std::vector<uint32_t>& occluders,
                           const std::vector<Eigen::Vector3f>& points,
                           const Eigen::Vector3f& center, float radius,
                           const Eigen::Vector3f& rough_up, float* horizontal_radius);

// The height (along frame.up) of the plane the object stands on, from the occluder surfels that
// face up near and just below its bottom; nullopt when none qualifies.
std::optional<float> SupportHeight(const GaussianCloud& cloud,
                                   const std::vector<uint32_t>& occluders, const ObjectFrame& frame,
                                   float horizontal_radius);

}  // namespace instascene::generation
