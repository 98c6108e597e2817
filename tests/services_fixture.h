// tests/services_fixture.h: the services wired together in one process for the integration
// tests (store, scheduler, Objects service behind one gRPC server; a tiny scene uploaded; workers
// on demand), and two test stages downstream of segment ("crop" per instance, "collect" joining
// them) that exercise the DAG.
#pragma once

#include <gtest/gtest.h>

#include <atomic>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "common/core/testing/temp_dir.h"
#include "common/rpc/server.h"
#include "common/rpc/status.h"
#include "common/store/manifest.h"
#include "instascene/v1/scheduler.grpc.pb.h"
#include "services/objects/objects_service.h"
#include "services/scheduler/scheduler_service.h"
#include "services/scheduler/sqlite_queue_store.h"
#include "services/store/remote_blob_store.h"
#include "services/store/store_service.h"
#include "services/worker/stage_worker.h"

namespace instascene::services_testing {

// Crop fails (retryable) for item 0 this many more times.
extern std::atomic<int> crop_failures_left;

// "crop" runs once per instance and writes the instance's Gaussian count; "collect" joins every
// crop.
absl::Status RegisterTestStages(pipeline::StageRegistry* stages);

class ServicesTest : public ::testing::Test {
 protected:
  void SetUp() override;
  void TearDown() override;

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

}  // namespace instascene::services_testing
