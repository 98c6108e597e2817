// services/decomposition/stage_params.h: the `decompose` stage as every binary can link it: its
// spec (no inputs but the scene) and its one parameter codec over DecompositionOptions. Light:
// no rasterizer, no image library (the scheduler validates with it).
#pragma once

#include "services/decomposition/options.h"
#include "services/pipeline/stage.h"

namespace instascene::decomposition {

const pipeline::ParamCodec<DecompositionOptions>& DecomposeCodec();
pipeline::StageSpec DecomposeSpec();

}  // namespace instascene::decomposition
