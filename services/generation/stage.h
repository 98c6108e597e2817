// services/generation/stage.h: the runnable `complete` stage (one job per segmented instance).
#pragma once

#include "services/generation/completion.h"
#include "services/generation/stage_params.h"
#include "services/pipeline/stage.h"

namespace instascene::generation {

// The completion options a job's parameters stand for.
CompletionOptions ToCompletionOptions(const CompleteStageOptions& options);

pipeline::StageDefinition CompleteStage();

}  // namespace instascene::generation
