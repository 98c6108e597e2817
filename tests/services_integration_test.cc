// The services wired together in one process over gRPC (services_fixture.h): workers run a
// pipeline; the DAG fans out one job per instance and fans in a join (test stages registered
// there); the Objects service answers clicks on the pipeline's result like the offline query index.
#include <gtest/gtest.h>

#include <atomic>
#include <fstream>
#include <set>

#include "common/core/testing/files.h"
#include "common/rpc/status.h"
#include "common/store/manifest.h"
#include "grpc/health/v1/health.grpc.pb.h"
#include "instascene/v1/objects.grpc.pb.h"
#include "services/objects/objects_service.h"
#include "services/objects/query_index.h"
#include "services/worker/stage_worker.h"
#include "tests/services_fixture.h"

namespace instascene {
namespace {
using instascene::testing::CountFiles;
using instascene::testing::RandomBytes;
using services_testing::crop_failures_left;
using services_testing::ServicesTest;

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
