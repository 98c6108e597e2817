#include "tests/services_fixture.h"

#include <filesystem>
#include <fstream>

#include "common/core/status.h"
#include "common/rpc/status.h"
#include "common/synth/scene_writer.h"
#include "services/stages/all_stages.h"

namespace instascene::services_testing {
namespace {
namespace fs = std::filesystem;

absl::StatusOr<nlohmann::json> AnyParameters(const nlohmann::json& p) {
  if (!p.is_object()) return absl::InvalidArgumentError("parameters must be an object");
  return p;
}

}  // namespace

std::atomic<int> crop_failures_left{0};

absl::Status RegisterTestStages(pipeline::StageRegistry* stages) {
  pipeline::StageSpec crop;
  crop.kind = "crop";
  crop.inputs = {{"segment", pipeline::InputMode::kEach}};
  crop.canonicalize = AnyParameters;
  RETURN_IF_ERROR(stages->Add(
      {crop, [](const pipeline::StageContext& c) -> absl::StatusOr<pipeline::StageResult> {
         if (c.item == 0 && crop_failures_left.fetch_sub(1) > 0)
           return absl::UnavailableError("crop: simulated worker crash");
         ASSIGN_OR_RETURN(std::string segment, c.Input("segment"));
         std::ifstream in(fs::path(segment) / "instances.json");
         const nlohmann::json instances = nlohmann::json::parse(in);
         fs::create_directories(c.out_dir);
         std::ofstream(fs::path(c.out_dir) / "crop.json")
             << nlohmann::json(
                    {{"item", c.item}, {"gaussians", instances.at(c.item).at("gaussians")}})
                    .dump();
         return pipeline::StageResult{};
       }}));
  pipeline::StageSpec collect;
  collect.kind = "collect";
  collect.inputs = {{"crop", pipeline::InputMode::kAll}};
  collect.canonicalize = AnyParameters;
  return stages->Add(
      {collect, [](const pipeline::StageContext& c) -> absl::StatusOr<pipeline::StageResult> {
         nlohmann::json all = nlohmann::json::array();
         for (const std::string& dir : c.AllInputs("crop")) {
           std::ifstream in(fs::path(dir) / "crop.json");
           all.push_back(nlohmann::json::parse(in));
         }
         fs::create_directories(c.out_dir);
         std::ofstream(fs::path(c.out_dir) / "collected.json") << all.dump();
         return pipeline::StageResult{};
       }});
}

void ServicesTest::SetUp() {
  root_ = temp_.str();
  store::StoreOptions store_options;
  store_options.max_blob_bytes = 4 << 20;
  store_ = std::move(*store::FilesystemBlobStore::Open(root_ + "/store", store_options));
  scheduler::QueueOptions queue_options;
  queue_options.lease_ms = 5000;
  queue_ = std::move(*scheduler::OpenSqliteJobQueue(root_ + "/jobs.db", queue_options));
  ASSERT_TRUE(stages::RegisterStages(&stages_).ok());
  ASSERT_TRUE(RegisterTestStages(&stages_).ok());
  store_service_ = std::make_unique<store_service::StoreService>(store_.get());
  scheduler_service_ = std::make_unique<scheduler::SchedulerService>(
      queue_.get(), store_.get(), &stages_, scheduler::SchedulerServiceOptions{});
  objects_service_ = std::make_unique<objects::ObjectsService>(
      store_.get(), [this](const std::string& scene) -> absl::StatusOr<v1::Scene> {
        v1::GetSceneRequest request;
        request.set_scene(scene);
        v1::Scene answer;
        grpc::ClientContext context;
        RETURN_IF_ERROR(rpc::FromGrpcStatus(scheduler_->GetScene(&context, request, &answer)));
        return answer;
      });
  auto server = rpc::Server::Start(
      {"127.0.0.1:0"}, {store_service_.get(), scheduler_service_.get(), objects_service_.get()},
      {"instascene.v1.ContentStore", "instascene.v1.Scheduler", "instascene.v1.Objects"});
  ASSERT_TRUE(server.ok()) << server.status();
  server_ = std::move(*server);
  channel_ = rpc::Connect(server_->address());
  remote_ = std::move(*store_service::RemoteBlobStore::Connect(channel_));
  scheduler_ = v1::Scheduler::NewStub(channel_);

  scene_dir_ = root_ + "/scene";
  auto generated = GenerateClutterScene(*ClutterPreset("tiny"));
  ASSERT_TRUE(generated.ok());
  ASSERT_TRUE(WriteClutterScene(*generated, scene_dir_).ok());
  auto manifest = store::SceneManifestFromDirectory(scene_dir_);
  ASSERT_TRUE(manifest.ok());
  auto upload = store::UploadManifest(*remote_, *manifest, scene_dir_);
  ASSERT_TRUE(upload.ok()) << upload.status();
  scene_manifest_ = upload->manifest;
}

void ServicesTest::TearDown() {
  for (auto& w : workers_) w->Drain(std::chrono::milliseconds(0));
  scheduler_service_->Stop();
  server_->Drain(std::chrono::milliseconds(100));
}

}  // namespace instascene::services_testing
