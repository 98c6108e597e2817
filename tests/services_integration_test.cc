// The services wired together in one process over gRPC (loopback / in-process channels): bad
// requests are refused with the right status and leave no trace; workers run a pipeline; the
// training service answers click queries like the offline query index.
#include <gtest/gtest.h>

#include <filesystem>
#include <thread>

#include "common/core/testing/files.h"
#include "common/core/testing/temp_dir.h"
#include "common/rpc/server.h"
#include "common/rpc/status.h"
#include "common/store/manifest.h"
#include "common/synth/scene_writer.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "instascene/v1/training.grpc.pb.h"
#include "services/scheduler/scheduler_service.h"
#include "services/scheduler/sqlite_job_queue.h"
#include "services/store/remote_blob_store.h"
#include "services/store/store_service.h"
#include "services/training/query.h"
#include "services/training/training_service.h"
#include "services/worker/stage_worker.h"

namespace instascene {
namespace {
namespace fs = std::filesystem;
using instascene::testing::CountFiles;
using instascene::testing::RandomBytes;

class ServicesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = testing::FreshTempDir("services_integration");
    store::StoreOptions store_options;
    store_options.max_blob_bytes = 4 << 20;
    store_ = std::move(*store::FilesystemBlobStore::Open(root_ + "/store", store_options));
    scheduler::QueueOptions queue_options;
    queue_options.lease_ms = 5000;
    queue_ = std::move(*scheduler::SqliteJobQueue::Open(root_ + "/jobs.db", queue_options));
    store_service_ = std::make_unique<store_service::StoreService>(store_.get());
    scheduler_service_ = std::make_unique<scheduler::SchedulerService>(
        queue_.get(), store_.get(), scheduler::SchedulerServiceOptions{});
    training_service_ =
        std::make_unique<training::TrainingService>(store_.get(), root_ + "/query", nullptr);
    auto server = rpc::Server::Start(
        {"127.0.0.1:0"}, {store_service_.get(), scheduler_service_.get(), training_service_.get()},
        {"instascene.v1.ContentStore", "instascene.v1.Scheduler", "instascene.v1.Training"});
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
                      v1::SubmitPipelineResponse* response) {
    v1::SubmitPipelineRequest request;
    rpc::ToProto(manifest, request.mutable_scene_manifest());
    request.set_scene("tiny");
    request.set_parameters_json(params);
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

  std::string root_, scene_dir_;
  std::unique_ptr<store::FilesystemBlobStore> store_;
  std::unique_ptr<scheduler::SqliteJobQueue> queue_;
  std::unique_ptr<store_service::StoreService> store_service_;
  std::unique_ptr<scheduler::SchedulerService> scheduler_service_;
  std::unique_ptr<training::TrainingService> training_service_;
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
  EXPECT_EQ(check("instascene.v1.Training"), kServing);
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
  const std::vector<Case> cases = {
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
  ASSERT_TRUE(queue_->Release((*lease)->job.id, (*lease)->token, "test").ok());

  // Nothing was queued, nothing half-written remains, the good jobs are untouched.
  EXPECT_EQ(queue_->List({})->size(), 3u);
  for (const v1::Job& j : good.jobs()) {
    const v1::Job now = GetJob(j.id());
    EXPECT_EQ(now.state(), v1::JOB_STATE_QUEUED);
    EXPECT_EQ(now.attempts(), 0);
  }
  EXPECT_EQ(store_->Stats()->blob_count, blobs_before + 3);  // the three manifests put above
  EXPECT_EQ(CountFiles(root_ + "/store/uploads"), 0u);
  EXPECT_EQ(CountFiles(root_ + "/store/tmp"), 0u);
}

TEST_F(ServicesTest, WorkersRunThePipelineAndTrainingAnswersClicks) {
  for (const std::vector<std::string>& kinds :
       {std::vector<std::string>{"decompose"}, std::vector<std::string>{"train", "segment"}}) {
    worker::WorkerOptions options;
    options.kinds = kinds;
    options.work_dir = root_ + "/work";
    options.poll_interval_ms = 20;
    options.heartbeat_interval_ms = 100;
    workers_.push_back(std::make_unique<worker::StageWorker>(options, remote_.get()));
    workers_.back()->Start(channel_);
  }
  v1::SubmitPipelineResponse response;
  ASSERT_TRUE(
      Submit(scene_manifest_, R"({"train":{"iterations":40,"samples":512}})", &response).ok());
  const std::string segment = response.jobs(2).id();
  v1::Job job;
  for (int i = 0; i < 600; ++i) {  // 60 s at most
    job = GetJob(segment);
    if (job.state() >= v1::JOB_STATE_SUCCEEDED) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED) << job.error();
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
  auto index = training::QueryIndex::Build(*scene, *cloud, *result);
  ASSERT_TRUE(index.ok());
  auto stub = v1::Training::NewStub(channel_);
  int hits = 0;
  for (int y = 4; y < scene->views[2].camera.height; y += 9) {
    for (int x = 4; x < scene->views[2].camera.width; x += 9) {
      v1::QueryRequest q;
      rpc::ToProto(scene_manifest_, q.mutable_scene_manifest());
      *q.mutable_result_manifest() = job.output_manifest();
      q.set_view(scene->views[2].name);
      q.set_x(x);
      q.set_y(y);
      v1::QueryResponse answer;
      grpc::ClientContext context;
      ASSERT_TRUE(stub->Query(&context, q, &answer).ok());
      const auto expected = (*index)->Click(2, x, y);
      EXPECT_EQ(answer.instance(), expected->instance) << x << "," << y;
      hits += answer.instance() != 0;
    }
  }
  EXPECT_GT(hits, 0);
  // A click outside the image is out of range.
  v1::QueryRequest bad;
  rpc::ToProto(scene_manifest_, bad.mutable_scene_manifest());
  *bad.mutable_result_manifest() = job.output_manifest();
  bad.set_view(scene->views[2].name);
  bad.set_x(100000);
  v1::QueryResponse ignored;
  grpc::ClientContext context;
  EXPECT_EQ(stub->Query(&context, bad, &ignored).error_code(), grpc::StatusCode::OUT_OF_RANGE);
}

}  // namespace
}  // namespace instascene
