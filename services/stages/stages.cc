#include "common/core/status.h"
#include "services/decomposition/stage.h"
#include "services/stages/all_stages.h"
#include "services/training/stage.h"

namespace instascene::stages {

absl::Status RegisterStages(pipeline::StageRegistry* registry) {
  RETURN_IF_ERROR(registry->Add(decomposition::DecomposeStage()));
  RETURN_IF_ERROR(registry->Add(training::TrainStage()));
  return registry->Add(training::SegmentStage());
}

}  // namespace instascene::stages
