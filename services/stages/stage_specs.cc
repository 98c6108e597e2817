#include "common/core/status.h"
#include "services/decomposition/stage_params.h"
#include "services/generation/stage_params.h"
#include "services/objects/stage_params.h"
#include "services/stages/all_stages.h"
#include "services/training/stage_params.h"

namespace instascene::stages {

absl::Status RegisterStageSpecs(pipeline::StageRegistry* registry) {
  RETURN_IF_ERROR(registry->Add({decomposition::DecomposeSpec(), nullptr}));
  RETURN_IF_ERROR(registry->Add({training::TrainSpec(), nullptr}));
  RETURN_IF_ERROR(registry->Add({training::SegmentSpec(), nullptr}));
  RETURN_IF_ERROR(registry->Add({generation::CompleteSpec(), nullptr}));
  return registry->Add({objects::ExportSpec(), nullptr});
}

}  // namespace instascene::stages
