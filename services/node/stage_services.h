// services/node/stage_services.h: the stage services this project ships, for the binaries that
// host them: decomposition (decompose jobs), training (train and segment jobs),
// generation (complete jobs, one per object) and objects (export jobs and the Objects
// service: objects by id, point, click or ray). Links the stage libraries; the scheduler
// binary does not link this.
#pragma once

#include <vector>

#include "services/node/node.h"

namespace instascene::node {

StageService DecompositionStageService();
StageService TrainingStageService();
StageService GenerationStageService();
StageService ObjectsStageService();  // export jobs + the Objects service (lookups)
std::vector<StageService> AllStageServices();

}  // namespace instascene::node
