#include "services/node/stage_services.h"

#include "services/decomposition/decomposition_service.h"
#include "services/generation/generation_service.h"
#include "services/training/training_service.h"

namespace instascene::node {

StageService DecompositionStageService() {
  return {"decomposition",
          "instascene.v1.Decomposition",
          {"decompose"},
          [](const worker::StageWorker* worker, store::BlobStore*, const std::string&) {
            return std::make_unique<decomposition::DecompositionService>(worker);
          }};
}

StageService TrainingStageService() {
  return {
      "training",
      "instascene.v1.Training",
      {"train", "segment"},
      [](const worker::StageWorker* worker, store::BlobStore* store, const std::string& work_dir) {
        return std::make_unique<training::TrainingService>(store, work_dir, worker);
      }};
}

StageService GenerationStageService() {
  return {"generation",
          "instascene.v1.Generation",
          {"complete", "export"},  // export: until the objects service hosts it (issue 15)
          [](const worker::StageWorker* worker, store::BlobStore*, const std::string&) {
            return std::make_unique<generation::GenerationService>(worker);
          }};
}

std::vector<StageService> AllStageServices() {
  return {DecompositionStageService(), TrainingStageService(), GenerationStageService()};
}

}  // namespace instascene::node
