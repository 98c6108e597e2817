// services/objects/convex_hull.h: 3D convex hulls with Qhull (Debian's reentrant libqhull_r: the
// standard implementation, robust to degenerate input), as closed outward-oriented triangle meshes,
// and point-in-hull tests. Thread-safe (one qhull context per call).
#pragma once

#include <vector>

#include <Eigen/Dense>

#include "absl/status/statusor.h"
#include "common/geometry/triangle_mesh.h"

namespace instascene::objects {

// FailedPrecondition for fewer than 4 points or points that span no volume (flat, collinear).
absl::StatusOr<TriangleMesh> ConvexHull(const std::vector<Eigen::Vector3f>& points);

// Signed distance of `p` to the hull's boundary planes: the largest plane distance (> 0 outside).
float HullSignedDistance(const TriangleMesh& hull, const Eigen::Vector3f& p);

}  // namespace instascene::objects
