// services/node/stage_services.h: the stage services this project ships, for the binaries that
// host them: decomposition (decompose jobs), training (train and segment jobs, click and point
// queries) and generation (complete jobs, one per object). Links the stage libraries; the scheduler
// binary does not link this.
#pragma once

#include <vector>

#include "services/node/node.h"

namespace instascene::node {

StageService DecompositionStageService();
StageService TrainingStageService();
StageService GenerationStageService();
std::vector<StageService> AllStageServices();

}  // namespace instascene::node
