// services/objects/convex_decomposition.h: approximate convex decomposition of a closed mesh into a
// bounded number of convex parts, for collision proxies that keep concavities (a cup stays a cup,
// not a solid block). No Debian package offers one (V-HACD and CoACD are not packaged), so this is
// a small hierarchical voxel method: the mesh's interior is voxelised (Embree ray parity), then the
// part whose convex hull wastes the most volume is split, first into connected components, else by
// the axis-aligned plane that minimises the two halves' hull volumes, until every part is convex
// enough (hull volume within `max_concavity` of its voxel volume) or `max_parts` is reached. Parts
// are the hulls of their voxels' corners, so together they cover the interior (conservative by at
// most one voxel). Deterministic; thread-safe.
#pragma once

#include <vector>

#include "absl/status/statusor.h"
#include "common/geometry/triangle_mesh.h"

namespace instascene::objects {

struct ConvexDecompositionOptions {
  int resolution = 40;  // voxels along the longest side
  int max_parts = 12;
  double max_concavity = 0.2;  // a part is done when 1 - voxel volume / hull volume is below
  int split_candidates = 9;    // cut positions tried per axis

  absl::Status Validate() const;
};

// The convex parts, each a closed outward-oriented mesh in the input's coordinates.
absl::StatusOr<std::vector<TriangleMesh>> ConvexDecomposition(
    const TriangleMesh& mesh, const ConvexDecompositionOptions& options = {});

}  // namespace instascene::objects
