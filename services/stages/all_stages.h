// services/stages/all_stages.h: the stages this project ships, registered in one place, in
// pipeline order. Two libraries: instascene_stage_specs registers specs and codecs only (the
// scheduler: validation without the stage libraries' dependencies); instascene_stages registers
// the runnable stages (workers, `instascene run`, `instascene serve`).
#pragma once

#include "services/pipeline/registry.h"

namespace instascene::stages {

// decompose -> train -> segment -> complete (per object), specs only.
absl::Status RegisterStageSpecs(pipeline::StageRegistry* registry);
// The same stages with their run functions.
absl::Status RegisterStages(pipeline::StageRegistry* registry);

}  // namespace instascene::stages
