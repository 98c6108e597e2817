// common/mesh/surfel_snap.h: moves a fused mesh's vertices onto the surface its surfels sample.
//
// A mesh fused from renders of splats stands where the rendered footprints reach, not where the
// surfel centres lie: past a silhouette a stack of discs keeps alpha above the fusion's threshold
// a fraction of a sigma beyond the true surface, and the grid quantises the rest. 2DGS surfel
// centres lie on the surface. Each vertex is moved along its normal onto the outermost layer of
// the surfel centres around it that face its way (a moving-least-squares projection that keeps
// the two sides of a thin wall apart), the move bounded and smoothed over the mesh so that a few
// stray surfels cannot pull a spike. Stateless, thread-safe.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "common/geometry/triangle_mesh.h"

namespace instascene {

struct SurfelSnapOptions {
  float radius = 0.0f;  // neighbourhood of a vertex (world units, > 0)
  // The layer: facing surfels within this, along the normal, of the min_surfels-th outermost
  // (on either side: fewer strays standing farther out neither define it nor count in it).
  float layer = 0.0f;
  float max_move = 0.0f;  // bound on a vertex's move (world units, > 0)
  float min_cos = 0.7f;   // a surfel faces the vertex's way when |n_surfel . n_vertex| >= this
  int min_surfels = 3;    // fewer facing surfels around a vertex: it stays (a closed hole)
  int smooth_passes = 2;  // passes averaging the moves over each vertex's 1-ring
  // Then a vertex farther than this from every surfel centre (past the edge of the sampled
  // surface: a fused lip over a rim or a corner) is pulled towards the nearest centre until it is
  // this far, by at most max_move (smoothed likewise). 0 = off.
  float reach = 0.0f;
  // Vertices flagged `fixed` move only across this unit direction (an object's support's up):
  // along the part of their normal perpendicular to it (where that part is at least 0.3 of it),
  // onto the facing surfels' layer, the layer's offsets fitted by a weighted line over their
  // height along this direction and taken at the vertex's own (a rim has its side's surfels only
  // above it; on a side that narrows upwards their mean stands inside the rim). A flat base stays
  // flat and its rim reaches the surfels. Zero: fixed vertices do not move. Not pulled by `reach`.
  Eigen::Vector3f slide_normal = Eigen::Vector3f::Zero();
};

// Moves the vertices of `mesh` (a closed or open triangle mesh; normals taken outward by the sign
// of its volume) onto the surfel centres `points` with unit normals `normals` (either sign).
// Vertices flagged in `fixed` (empty, or one flag per vertex) do not move, or slide within their
// plane (`slide_normal`; an object's base on its support). Returns how many vertices moved.
size_t SnapToSurfels(const std::vector<Eigen::Vector3f>& points,
                     const std::vector<Eigen::Vector3f>& normals, const SurfelSnapOptions& options,
                     TriangleMesh* mesh, const std::vector<uint8_t>& fixed = {});

// A base's outer ring on its support (vertices flagged in `rim`) moves outward only, across
// `options.slide_normal` (the support's up), onto its side's foot: the outermost layer of the
// surfels facing its way, taken down the slope their normals give to the vertex's height, where
// that side narrows upwards (a cone's, by at least 6 degrees). A side's lowest surfels stand a
// few millimetres above the support, on a cone inside the true rim, and a fused floor's rounded
// corner, or a clamp to the surfel centres' extremes, left the ring there. A vertex moves along
// the part of its outward normal across the slide normal (at least 0.05 of it: the inside of a
// flat base has none), not at all where the foot stands farther than max_move (the vertex is not
// at that side's foot) or where too few surfels face its way; the moves are not smoothed (the
// layer averages the side's surfels around each vertex). A vertical side (its surfels reach the
// support's height already) or one that widens upwards (a bowl's foot, a torus's underside)
// leaves the ring where it is. Returns how many vertices moved.
size_t ExtendRimToSide(const std::vector<Eigen::Vector3f>& points,
                       const std::vector<Eigen::Vector3f>& normals,
                       const SurfelSnapOptions& options, TriangleMesh* mesh,
                       const std::vector<uint8_t>& rim);

}  // namespace instascene
