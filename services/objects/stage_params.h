// services/objects/stage_params.h: the `export` stage as every binary can link it: its spec and
// parameter codec. A join over every `complete` job of a scene: the scene's object catalogue.
#pragma once

#include <cstdint>

#include "services/pipeline/stage.h"

namespace instascene::objects {

struct ExportStageOptions {
  double density = 500;           // kg/m³, for mass and inertia
  int surface_points = 4096;      // points.ply samples per object
  int collision_parts = 12;       // most convex parts per object
  int collision_resolution = 40;  // voxels along an object's longest side
  uint64_t seed = 1;
};

const pipeline::ParamCodec<ExportStageOptions>& ExportCodec();
pipeline::StageSpec ExportSpec();  // input: all items of complete

}  // namespace instascene::objects
