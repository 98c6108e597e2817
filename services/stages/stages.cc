#include "common/core/status.h"
#include "services/decomposition/stage.h"
#include "services/generation/stage.h"
#include "services/objects/stage.h"
#include "services/stages/all_stages.h"
#include "services/training/stage.h"

namespace instascene::stages {

absl::Status RegisterStages(pipeline::StageRegistry* registry) {
  RETURN_IF_ERROR(registry->Add(decomposition::DecomposeStage()));
  RETURN_IF_ERROR(registry->Add(training::TrainStage()));
  RETURN_IF_ERROR(registry->Add(training::SegmentStage()));
  RETURN_IF_ERROR(registry->Add(generation::CompleteStage()));
  return registry->Add(objects::ExportStage());
}

}  // namespace instascene::stages
