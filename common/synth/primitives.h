// common/synth/primitives.h: procedural object shapes as closed triangle meshes with UVs.
//
// Every shape is built in its object frame: z up, resting on z = 0, centred on the z axis. Solids
// of revolution (sphere, cylinder, cone, torus, bottle, cup, bowl) come from one lathe routine over
// a 2D profile; cups and bowls have real walls (outer and inner surface, rim), so they are
// watertight like the rest. Stateless, thread-safe.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/geometry/triangle_mesh.h"

namespace instascene {

// The first eight are symmetric (boxes: two mirror planes; the rest: solids of revolution). The
// last three have no symmetry a completion prior could exploit: kMug (a cup with a handle on one
// side), kLBlock (two boxes of different heights in an L), kIrregular (a box sheared, slanted and
// twisted).
enum class ShapeKind {
  kBox,
  kSphere,
  kCylinder,
  kCone,
  kTorus,
  kBottle,
  kCup,
  kBowl,
  kMug,
  kLBlock,
  kIrregular
};

std::string ShapeKindName(ShapeKind kind);

struct ShapeSpec {
  ShapeKind kind = ShapeKind::kBox;
  // kBox, kLBlock, kIrregular: full extents (x, y, z). Revolution shapes and kMug: (radius,
  // unused, height); kTorus: (major radius, tube radius, unused); kSphere: (radius, unused,
  // unused). Metres.
  Eigen::Vector3f size = Eigen::Vector3f::Ones();

  float FootprintRadius() const;  // radius of the bounding circle in the xy plane
  float Height() const;           // z extent
};

// A closed mesh of the shape; `segments` is the angular resolution of revolution shapes.
TriangleMesh MakeShapeMesh(const ShapeSpec& spec, int segments = 48);

// The points where the shape's surface closes to a sharp tip (a cone's apex), in the shape's frame
// (MakeShapeMesh's), each with the mesh's UV there. Empty for shapes without one.
struct ShapeTip {
  Eigen::Vector3f position;
  Eigen::Vector2f uv;
};
std::vector<ShapeTip> ShapeTips(const ShapeSpec& spec);

// A sphere of `radius` centred at the origin (MakeShapeMesh's rests on z = 0).
TriangleMesh MakeCenteredSphere(float radius, int segments = 48);

// A flat rectangle in the xy plane centred at the origin (normal +z), split into cells.
TriangleMesh MakeRectangle(float size_x, float size_y, int cells_x, int cells_y);

// A closed lathe: `profile` is a polyline (radius, z) revolved about the z axis; UV u = angle,
// v = profile arc length fraction.
TriangleMesh MakeLathe(const std::vector<Eigen::Vector2f>& profile, int segments, bool closed_loop);

}  // namespace instascene
