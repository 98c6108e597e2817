// The services wired together in one process over gRPC (loopback / in-process channels): bad
// requests are refused with the right status and leave no trace; workers run a pipeline; the DAG
// fans out one job per instance and fans in a join (test stages registered here); the Objects
// service answers clicks on the pipeline's result like the offline query index.
#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <set>

#include "common/core/status.h"
#include "common/core/testing/files.h"
#include "common/core/testing/temp_dir.h"
#include "common/rpc/server.h"
#include "common/rpc/status.h"
#include "common/store/manifest.h"
#include "common/synth/scene_writer.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "instascene/v1/objects.grpc.pb.h"
#include "services/objects/objects_service.h"
#include "services/objects/query_index.h"
#include "services/scheduler/scheduler_service.h"
#include "services/scheduler/sqlite_queue_store.h"
#include "services/stages/all_stages.h"
#include "services/store/remote_blob_store.h"
#include "services/store/store_service.h"
#include "services/worker/stage_worker.h"

namespace instascene {
namespace {
namespace fs = std::filesystem;
using instascene::testing::CountFiles;
using instascene::testing::RandomBytes;

absl::StatusOr<nlohmann::json> AnyParameters(const nlohmann::json& p) {
  if (!p.is_object()) return absl::InvalidArgumentError("parameters must be an object");
  return p;
}

// Test stages downstream of segment: "crop" runs once per instance and writes the instance's
// Gaussian count; "collect" joins every crop. Crop fails once (retryable) for item 0 when asked.
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

class ServicesTest : public ::testing::Test {
 protected:
  void SetUp() override {
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
        store_.get(),
        [this](const std::string& scene) -> absl::StatusOr<v1::Scene> {
          v1::GetSceneRequest request;
          request.set_scene(scene);
          v1::Scene answer;
          grpc::ClientContext context;
          RETURN_IF_ERROR(rpc::FromGrpcStatus(scheduler_->GetScene(&context, request, &answer)));
          return answer;
        },
        root_ + "/objects");
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

  void TearDown() override {
    for (auto& w : workers_) w->Drain(std::chrono::milliseconds(0));
    scheduler_service_->Stop();
    server_->Drain(std::chrono::milliseconds(100));
  }

  grpc::Status Submit(const store::Digest& manifest, const std::string& params,
                      v1::SubmitPipelineResponse* response,
                      const std::vector<std::string>& stages = {"decompose", "train", "segment"}) {
    v1::SubmitPipelineRequest request;
    rpc::ToProto(manifest, request.mutable_scene_manifest());
    request.set_scene("tiny");
    request.set_parameters_json(params);
    for (const std::string& s : stages) request.add_stages(s);
    grpc::ClientContext context;
    return scheduler_->SubmitPipeline(&context, request, response);
  }

  v1::Job GetJob(const std::string& id) {
    v1::GetJobRequest request;
    request.set_job_id(id);
    v1::Job job;
    grpc::ClientContext context;
    EXPECT_TRUE(scheduler_->GetJob(&context, request, &job).ok());
    return job;
  }

  void StartWorker(std::vector<std::string> kinds) {
    worker::WorkerOptions options;
    options.kinds = std::move(kinds);
    options.work_dir = root_ + "/work";
    options.poll_interval_ms = 20;
    options.heartbeat_interval_ms = 100;
    workers_.push_back(std::make_unique<worker::StageWorker>(options, remote_.get(), &stages_));
    workers_.back()->Start(channel_);
  }

  // Follows the scene's jobs (WatchJobs) until every one is final; returns them by id.
  std::map<std::string, v1::Job> WatchScene() {
    v1::WatchJobsRequest request;
    request.set_scene("tiny");
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
    auto reader = scheduler_->WatchJobs(&context, request);
    std::map<std::string, v1::Job> last;
    v1::Job job;
    while (reader->Read(&job)) last[job.id()] = job;
    EXPECT_TRUE(reader->Finish().ok());
    return last;
  }

  testing::ScopedTempDir temp_{"services_integration"};  // first member: removed last
  std::string root_, scene_dir_;
  pipeline::StageRegistry stages_;
  std::unique_ptr<store::FilesystemBlobStore> store_;
  std::unique_ptr<scheduler::JobQueue> queue_;
  std::unique_ptr<store_service::StoreService> store_service_;
  std::unique_ptr<scheduler::SchedulerService> scheduler_service_;
  std::unique_ptr<objects::ObjectsService> objects_service_;
  std::unique_ptr<rpc::Server> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<store_service::RemoteBlobStore> remote_;
  std::unique_ptr<v1::Scheduler::Stub> scheduler_;
  std::vector<std::unique_ptr<worker::StageWorker>> workers_;
  store::Digest scene_manifest_;
};

TEST_F(ServicesTest, HealthReportsEveryService) {
  auto health = grpc::health::v1::Health::NewStub(channel_);
  auto check = [&](const std::string& service) {
    grpc::health::v1::HealthCheckRequest request;
    request.set_service(service);
    grpc::health::v1::HealthCheckResponse response;
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
    const grpc::Status s = health->Check(&context, request, &response);
    return s.ok() ? static_cast<int>(response.status()) : -static_cast<int>(s.error_code());
  };
  constexpr int kServing = grpc::health::v1::HealthCheckResponse::SERVING;
  EXPECT_EQ(check(""), kServing);
  EXPECT_EQ(check("instascene.v1.Scheduler"), kServing);
  EXPECT_EQ(check("instascene.v1.ContentStore"), kServing);
  EXPECT_EQ(check("instascene.v1.Objects"), kServing);
  EXPECT_EQ(check("instascene.v1.Nope"), -static_cast<int>(grpc::StatusCode::NOT_FOUND));
}

TEST_F(ServicesTest, BadRequestsAreRejectedAndLeaveNoTrace) {
  // A good pipeline first: it must come through everything below untouched.
  v1::SubmitPipelineResponse good;
  ASSERT_TRUE(Submit(scene_manifest_, "", &good).ok());
  ASSERT_EQ(good.jobs_size(), 3);
  const auto blobs_before = store_->Stats()->blob_count;

  struct Case {
    std::string name;
    store::Digest manifest;
    std::string params;
    grpc::StatusCode code;
    std::string says;
  };
  auto put = [&](const std::string& bytes) {
    store::Digest d = store::ComputeDigest(bytes);
    EXPECT_TRUE(remote_->Put(d, bytes).ok());
    return d;
  };
  store::Manifest no_scene_json;
  no_scene_json.kind = "scene";
  no_scene_json.files["gaussians.ply"] = store::ComputeDigest("x");
  store::Manifest missing_blob = *store::ReadManifest(*store_, scene_manifest_);
  missing_blob.files["extra.bin"] = store::ComputeDigest("never uploaded");
  // A scene whose first view claims 16384 x 16384 pixels: over the per-view limit.
  store::Manifest huge_scene = *store::ReadManifest(*store_, scene_manifest_);
  nlohmann::json scene_json =
      nlohmann::json::parse(*store_->Read(huge_scene.files.at("scene.json")));
  scene_json["views"][0]["width"] = 16384;
  scene_json["views"][0]["height"] = 16384;
  huge_scene.files["scene.json"] = put(scene_json.dump());
  const std::vector<Case> cases = {
      {"a view of 268 megapixels", put(store::SerializeManifest(huge_scene)), "",
       grpc::StatusCode::RESOURCE_EXHAUSTED, "scene too large"},
      {"garbage manifest", put("this is not json"), "", grpc::StatusCode::INVALID_ARGUMENT,
       "malformed manifest"},
      {"scene manifest without scene.json", put(store::SerializeManifest(no_scene_json)), "",
       grpc::StatusCode::INVALID_ARGUMENT, "no scene.json"},
      {"manifest naming a blob the store lacks", put(store::SerializeManifest(missing_blob)), "",
       grpc::StatusCode::FAILED_PRECONDITION, "blobs the store lacks"},
      {"unknown manifest digest", store::ComputeDigest("nothing"), "", grpc::StatusCode::NOT_FOUND,
       "not in the store"},
      {"bad parameter", scene_manifest_, R"({"train":{"samples":-3}})",
       grpc::StatusCode::INVALID_ARGUMENT, "samples"},
      {"parameters not JSON", scene_manifest_, "{train", grpc::StatusCode::INVALID_ARGUMENT,
       "not valid JSON"},
  };
  {  // A scene name of 130 KB is refused (it would break every later job listing).
    v1::SubmitPipelineRequest request;
    rpc::ToProto(scene_manifest_, request.mutable_scene_manifest());
    request.set_scene(std::string(130000, 'n'));
    v1::SubmitPipelineResponse response;
    grpc::ClientContext context;
    const grpc::Status s = scheduler_->SubmitPipeline(&context, request, &response);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
  }
  for (const Case& c : cases) {
    v1::SubmitPipelineResponse response;
    const grpc::Status s = Submit(c.manifest, c.params, &response);
    EXPECT_EQ(s.error_code(), c.code) << c.name << ": " << s.error_message();
    EXPECT_NE(s.error_message().find(c.says), std::string::npos)
        << c.name << ": " << s.error_message();
  }
  // Uploads: corrupt and oversized blobs are refused.
  std::string bytes(1000, 'a');
  store::Digest wrong = store::ComputeDigest(bytes);
  bytes[10] = 'b';
  EXPECT_EQ(remote_->Put(wrong, bytes).code(), absl::StatusCode::kInvalidArgument);
  const std::string huge((4 << 20) + 1, 'h');
  EXPECT_EQ(remote_->Put(store::ComputeDigest(huge), huge).code(),
            absl::StatusCode::kResourceExhausted);
  // A worker cannot complete a job with an output the store lacks.
  auto lease = queue_->LeaseNext({"decompose"}, "test", 0);
  ASSERT_TRUE(lease.ok() && lease->has_value());
  v1::CompleteJobRequest complete;
  complete.set_job_id((*lease)->job.id);
  complete.set_lease_token((*lease)->token);
  rpc::ToProto(store::ComputeDigest("no such output"), complete.mutable_output_manifest());
  v1::CompleteJobResponse ignored;
  grpc::ClientContext context;
  const grpc::Status s = scheduler_->CompleteJob(&context, complete, &ignored);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << s.error_message();
  // Nor with a forged output: someone else's lease, a manifest of another stage, one naming blobs
  // the store lacks, one without the files its stage always writes.
  store::Manifest forged;
  forged.kind = "decompose";
  forged.files["result.json"] = put("{}");
  forged.files["labels.ply"] = put("ply");
  store::Manifest wrong_kind = forged;
  wrong_kind.kind = "segment";
  store::Manifest dangling = forged;
  dangling.files["decomposition.json"] = store::ComputeDigest("never uploaded either");
  struct Completion {
    std::string name, token;
    store::Digest output;
    grpc::StatusCode code;
    std::string says;
  };
  const std::vector<Completion> completions = {
      {"another lease's token", "not-the-token", put(store::SerializeManifest(forged)),
       grpc::StatusCode::FAILED_PRECONDITION, "lease token"},
      {"a segment manifest", (*lease)->token, put(store::SerializeManifest(wrong_kind)),
       grpc::StatusCode::INVALID_ARGUMENT, "of kind \"segment\""},
      {"a manifest naming a missing blob", (*lease)->token, put(store::SerializeManifest(dangling)),
       grpc::StatusCode::FAILED_PRECONDITION, "blobs the store lacks"},
      {"no decomposition.json", (*lease)->token, put(store::SerializeManifest(forged)),
       grpc::StatusCode::INVALID_ARGUMENT, "lacks decomposition.json"},
  };
  for (const Completion& c : completions) {
    complete.set_lease_token(c.token);
    rpc::ToProto(c.output, complete.mutable_output_manifest());
    grpc::ClientContext ctx;
    const grpc::Status bad = scheduler_->CompleteJob(&ctx, complete, &ignored);
    EXPECT_EQ(bad.error_code(), c.code) << c.name << ": " << bad.error_message();
    EXPECT_NE(bad.error_message().find(c.says), std::string::npos)
        << c.name << ": " << bad.error_message();
  }
  EXPECT_EQ(queue_->Get((*lease)->job.id)->state, scheduler::JobState::kLeased);
  ASSERT_TRUE(
      queue_->Fail((*lease)->job.id, (*lease)->token, scheduler::FailureKind::kReleased, "test")
          .ok());

  // Nothing was queued, nothing half-written remains, the good jobs are untouched.
  EXPECT_EQ(queue_->List({})->size(), 3u);
  for (const v1::Job& j : good.jobs()) {
    const v1::Job now = GetJob(j.id());
    EXPECT_EQ(now.state(), v1::JOB_STATE_QUEUED);
    EXPECT_EQ(now.attempts(), 0);
  }
  EXPECT_EQ(store_->Stats()->blob_count, blobs_before + 10);  // the blobs put above
  EXPECT_EQ(CountFiles(root_ + "/store/uploads"), 0u);
  EXPECT_EQ(CountFiles(root_ + "/store/tmp"), 0u);
}

TEST_F(ServicesTest, WorkersRunThePipelineAndTheObjectsServiceAnswersClicks) {
  StartWorker({"decompose"});
  StartWorker({"train", "segment"});
  v1::SubmitPipelineResponse response;
  ASSERT_TRUE(
      Submit(scene_manifest_, R"({"train":{"iterations":40,"samples":512}})", &response).ok());
  const std::string segment = response.jobs(2).id();
  WatchScene();
  const v1::Job job = GetJob(segment);
  ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED) << job.error();
  EXPECT_TRUE(workers_[0]->AwaitSucceeded(1, std::chrono::seconds(30)));
  EXPECT_TRUE(workers_[1]->AwaitSucceeded(2, std::chrono::seconds(30)));
  EXPECT_EQ(workers_[0]->succeeded(), 1);
  EXPECT_EQ(workers_[1]->succeeded(), 2);

  // The same click through the service and through a local index over the fetched result.
  const std::string result_dir = root_ + "/fetched";
  auto manifest = store::ReadManifest(*remote_, rpc::FromProto(job.output_manifest()));
  ASSERT_TRUE(manifest.ok());
  ASSERT_TRUE(store::MaterializeManifest(*remote_, *manifest, result_dir).ok());
  auto scene = ReadScene(scene_dir_);
  auto cloud = ReadSceneGaussians(*scene);
  auto result = ReadResult(result_dir, cloud->size());
  ASSERT_TRUE(result.ok()) << result.status();
  auto index = objects::QueryIndex::Build(*scene, *cloud, *result);
  ASSERT_TRUE(index.ok());
  auto stub = v1::Objects::NewStub(channel_);
  int hits = 0;
  for (int y = 4; y < scene->views[2].camera.height; y += 9) {
    for (int x = 4; x < scene->views[2].camera.width; x += 9) {
      v1::GetObjectRequest q;
      q.set_scene("tiny");
      q.mutable_selector()->mutable_click()->set_view(scene->views[2].name);
      q.mutable_selector()->mutable_click()->set_x(x);
      q.mutable_selector()->mutable_click()->set_y(y);
      v1::Object answer;
      grpc::ClientContext context;
      const grpc::Status status = stub->GetObject(&context, q, &answer);
      const auto expected = (*index)->Click(2, x, y);
      if (expected->instance == 0) {
        EXPECT_EQ(status.error_code(), grpc::StatusCode::NOT_FOUND) << x << "," << y;
        continue;
      }
      ASSERT_TRUE(status.ok()) << status.error_message();
      EXPECT_EQ(answer.id(), expected->instance) << x << "," << y;
      EXPECT_EQ(answer.source(), "segment");  // no export in this pipeline
      ++hits;
    }
  }
  EXPECT_GT(hits, 0);
  // A click outside the image is out of range.
  v1::GetObjectRequest bad;
  bad.set_scene("tiny");
  bad.mutable_selector()->mutable_click()->set_view(scene->views[2].name);
  bad.mutable_selector()->mutable_click()->set_x(100000);
  v1::Object ignored;
  grpc::ClientContext context;
  EXPECT_EQ(stub->GetObject(&context, bad, &ignored).error_code(), grpc::StatusCode::OUT_OF_RANGE);
}

TEST_F(ServicesTest, TheDagFansOutPerInstanceAndFansInOnce) {
  StartWorker({"decompose"});
  StartWorker({"train", "segment"});
  StartWorker({"crop", "collect"});
  crop_failures_left = 1;  // item 0's first attempt crashes: only it is retried
  const std::vector<std::string> all = {"decompose", "train", "segment", "crop", "collect"};
  const std::string params = R"({"train":{"iterations":30,"samples":256}})";
  v1::SubmitPipelineResponse response;
  ASSERT_TRUE(Submit(scene_manifest_, params, &response, all).ok());
  ASSERT_EQ(response.jobs_size(), 3);  // crop and collect wait for segment's instances
  std::map<std::string, v1::Job> jobs = WatchScene();
  const v1::Job segment = GetJob(response.jobs(2).id());
  ASSERT_EQ(segment.state(), v1::JOB_STATE_SUCCEEDED) << segment.error();
  const int64_t n = segment.items();
  ASSERT_GT(n, 1);
  std::set<int64_t> items;
  const v1::Job* collect = nullptr;
  for (const auto& [id, j] : jobs) {
    EXPECT_EQ(j.state(), v1::JOB_STATE_SUCCEEDED) << j.kind() << " " << j.error();
    if (j.kind() == "crop") {
      items.insert(j.item());
      EXPECT_EQ(j.parent(), segment.id());
      EXPECT_EQ(j.attempts(), j.item() == 0 ? 2 : 1) << "item " << j.item();
    }
    if (j.kind() == "collect") collect = &j;
  }
  EXPECT_EQ(static_cast<int64_t>(items.size()), n);
  ASSERT_NE(collect, nullptr);
  EXPECT_EQ(collect->dependencies_size(), n);

  // The scene is first-class: every stage's latest output without knowing a job id.
  v1::GetSceneRequest scene_request;
  scene_request.set_scene("tiny");
  v1::Scene scene;
  {
    grpc::ClientContext context;
    ASSERT_TRUE(scheduler_->GetScene(&context, scene_request, &scene).ok());
  }
  EXPECT_EQ(scene.outputs_size(), 4 + n);
  std::string collected_manifest;
  for (const v1::StageOutput& o : scene.outputs())
    if (o.kind() == "collect") collected_manifest = o.job_id();
  EXPECT_EQ(collected_manifest, collect->id());
  auto manifest = store::ReadManifest(*remote_, rpc::FromProto(collect->output_manifest()));
  ASSERT_TRUE(manifest.ok());
  ASSERT_TRUE(store::MaterializeManifest(*remote_, *manifest, root_ + "/collected").ok());
  std::ifstream in(root_ + "/collected/collected.json");
  const nlohmann::json collected = nlohmann::json::parse(in);
  ASSERT_EQ(static_cast<int64_t>(collected.size()), n);
  for (int64_t i = 0; i < n; ++i) EXPECT_EQ(collected[i]["item"], i);

  // Resubmission creates nothing.
  v1::SubmitPipelineResponse again;
  ASSERT_TRUE(Submit(scene_manifest_, params, &again, all).ok());
  EXPECT_EQ(again.jobs_size(), 3 + n + 1);
  for (int i = 0; i < again.jobs_size(); ++i) EXPECT_FALSE(again.created(i)) << i;

  // Without crop workers, a changed crop parameter queues n new children and a join; cancelling
  // the scene cancels every one of them.
  for (auto& w : workers_) w->Drain(std::chrono::milliseconds(0));
  v1::SubmitPipelineResponse changed;
  ASSERT_TRUE(Submit(scene_manifest_, R"({"train":{"iterations":30,"samples":256},"crop":{"v":2}})",
                     &changed, all)
                  .ok());
  int created = 0;
  for (int i = 0; i < changed.jobs_size(); ++i) created += changed.created(i);
  EXPECT_EQ(created, n + 1);
  v1::CancelSceneRequest cancel;
  cancel.set_scene("tiny");
  v1::CancelSceneResponse cancelled;
  {
    grpc::ClientContext context;
    ASSERT_TRUE(scheduler_->CancelScene(&context, cancel, &cancelled).ok());
  }
  EXPECT_EQ(cancelled.jobs_size(), n + 1);
  for (const v1::Job& j : cancelled.jobs()) EXPECT_EQ(j.state(), v1::JOB_STATE_CANCELLED);
}

}  // namespace
}  // namespace instascene
