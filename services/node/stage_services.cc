#include "services/node/stage_services.h"

#include "absl/strings/str_cat.h"
#include "common/rpc/status.h"
#include "instascene/v1/scheduler.grpc.pb.h"
#include "services/decomposition/decomposition_service.h"
#include "services/generation/generation_service.h"
#include "services/objects/objects_service.h"
#include "services/training/training_service.h"

namespace instascene::node {

StageService DecompositionStageService() {
  return {"decomposition",
          "instascene.v1.Decomposition",
          {"decompose"},
          [](const StageServiceContext& c) {
            return std::make_unique<decomposition::DecompositionService>(c.worker, c.auth);
          }};
}

StageService TrainingStageService() {
  return {
      "training", "instascene.v1.Training", {"train", "segment"}, [](const StageServiceContext& c) {
        return std::make_unique<training::TrainingService>(c.worker, c.auth);
      }};
}

StageService GenerationStageService() {
  return {"generation", "instascene.v1.Generation", {"complete"}, [](const StageServiceContext& c) {
            return std::make_unique<generation::GenerationService>(c.worker, c.auth);
          }};
}

StageService ObjectsStageService() {
  return {"objects", "instascene.v1.Objects", {"export"}, [](const StageServiceContext& c) {
            auto scheduler = c.scheduler;
            objects::SceneLookup lookup =
                [scheduler](const std::string& scene) -> absl::StatusOr<v1::Scene> {
              std::shared_ptr<grpc::Channel> channel = scheduler ? scheduler() : nullptr;
              if (channel == nullptr)
                return absl::UnavailableError("the objects service is starting: no scheduler yet");
              v1::GetSceneRequest request;
              request.set_scene(scene);
              v1::Scene answer;
              grpc::ClientContext context;
              context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
              const grpc::Status status =
                  v1::Scheduler::NewStub(channel)->GetScene(&context, request, &answer);
              if (!status.ok()) return rpc::FromGrpcStatus(status);
              return answer;
            };
            objects::ObjectsServiceOptions options;
            options.cache_bytes = c.index_cache_bytes;
            options.auth = c.auth;
            return std::make_unique<objects::ObjectsService>(c.store, std::move(lookup), options);
          }};
}

std::vector<StageService> AllStageServices() {
  return {DecompositionStageService(), TrainingStageService(), GenerationStageService(),
          ObjectsStageService()};
}

}  // namespace instascene::node
