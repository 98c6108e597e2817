#include "services/objects/stage_params.h"

namespace instascene::objects {

const pipeline::ParamCodec<ExportStageOptions>& ExportCodec() {
  using O = ExportStageOptions;
  static const auto* codec = [] {
    auto* c = new pipeline::ParamCodec<O>("export");
    c->Real("density", &O::density, 1.0, 20000.0,
            "Density for mass and inertia, kg/m^3 (per unit^3 when the scene is unscaled)")
        .Int("surface_points", &O::surface_points, 1, 1000000, "Surface samples per object")
        .Int("collision_parts", &O::collision_parts, 1, 64,
             "Most convex collision parts per object")
        .Int("collision_resolution", &O::collision_resolution, 8, 128,
             "Voxels along an object's longest side for the convex decomposition")
        .Int<uint64_t>("export_seed", &O::seed, 0, int64_t{1} << 53,
                       "Random seed of the surface samples");
    return c;
  }();
  return *codec;
}

pipeline::StageSpec ExportSpec() {
  pipeline::StageSpec spec = pipeline::MakeStageSpec(
      "export", "export",
      "Every completed object as robot-ready artefacts (glTF/Draco, STL, URDF, MJCF, collision "
      "parts, surface samples) in metres, and the scene's object catalogue",
      {{"complete", pipeline::InputMode::kAll}}, /*fans_out=*/false, ExportCodec());
  // Part of the default pipeline: a partial join, so an object whose completion failed (e.g. a
  // degenerate instance) is left out of the export (the Objects service answers it as a raw crop)
  // instead of failing the scene's export.
  spec.partial_join = true;
  spec.required_outputs = {"objects.json"};
  return spec;
}

}  // namespace instascene::objects
