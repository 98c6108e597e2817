// services/decomposition/stage.h: the `decompose` stage with its run function (links the
// decomposition library): scene -> decomposition directory (result format, per-view maps).
#pragma once

#include "services/pipeline/stage.h"

namespace instascene::decomposition {

pipeline::StageDefinition DecomposeStage();

}  // namespace instascene::decomposition
