// Authentication and tenants across the services in one process over loopback gRPC: every method
// of every service refuses a call without a valid token; roles limit what a token may call; two
// tenants share the store and the queue and see nothing of each other (scenes, jobs, blobs), while
// workers and admins see everything; a completed job's outputs are granted to its tenant only; a
// tenant's unfinished jobs are bounded.
#include <grpcpp/generic/generic_stub.h>
#include <gtest/gtest.h>

#include <future>

#include "common/auth/authenticator.h"
#include "common/auth/tokens.h"
#include "common/core/status.h"
#include "common/core/testing/temp_dir.h"
#include "common/rpc/server.h"
#include "common/rpc/status.h"
#include "common/store/manifest.h"
#include "common/synth/scene_writer.h"
#include "instascene/v1/objects.grpc.pb.h"
#include "services/decomposition/decomposition_service.h"
#include "services/generation/generation_service.h"
#include "services/objects/objects_service.h"
#include "services/scheduler/scheduler_service.h"
#include "services/scheduler/sqlite_queue_store.h"
#include "services/store/remote_blob_store.h"
#include "services/store/store_service.h"
#include "services/training/training_service.h"

namespace instascene {
namespace {

using auth::Role;

class AuthTest : public ::testing::Test {
 protected:
  static constexpr int64_t kQuota = int64_t{8} << 20;  // bytes one tenant may hold
  void SetUp() override {
    const std::string root = temp_.str();
    const std::string tokens = temp_.Sub("tokens.json");
    acme_ = *auth::CreateToken(tokens, Role::kClient, "acme", "");
    beta_ = *auth::CreateToken(tokens, Role::kClient, "beta", "");
    worker_ = *auth::CreateToken(tokens, Role::kWorker, "", "");
    admin_ = *auth::CreateToken(tokens, Role::kAdmin, "", "");
    auth_ = *auth::Authenticator::FromFile(tokens, std::chrono::milliseconds(0));  // no wait
    store::StoreOptions store_options;
    store_options.tenant_quota_bytes = kQuota;
    store_ = std::move(*store::FilesystemBlobStore::Open(root + "/store", store_options));
    scheduler::QueueOptions queue_options;
    queue_options.max_unfinished_per_tenant = 1;  // one job in flight per tenant
    queue_ = std::move(*scheduler::OpenSqliteJobQueue(root + "/jobs.db", queue_options));
    pipeline::StageSpec echo;
    echo.kind = "echo";
    echo.canonicalize = [](const nlohmann::json& p) -> absl::StatusOr<nlohmann::json> { return p; };
    ASSERT_TRUE(stages_.Add({echo, nullptr}).ok());
    store_service_ = std::make_unique<store_service::StoreService>(store_.get(), auth_.get());
    scheduler::SchedulerServiceOptions scheduler_options;
    scheduler_options.auth = auth_.get();
    scheduler_service_ = std::make_unique<scheduler::SchedulerService>(queue_.get(), store_.get(),
                                                                       &stages_, scheduler_options);
    objects::ObjectsServiceOptions objects_options;
    objects_options.auth = auth_.get();
    objects_service_ = std::make_unique<objects::ObjectsService>(
        store_.get(),
        [](const std::string& scene) -> absl::StatusOr<v1::Scene> {
          return absl::NotFoundError("scene " + scene + " has no results");
        },
        objects_options);
    decomposition_ = std::make_unique<decomposition::DecompositionService>(nullptr, auth_.get());
    training_ = std::make_unique<training::TrainingService>(nullptr, auth_.get());
    generation_ = std::make_unique<generation::GenerationService>(nullptr, auth_.get());
    auto server = rpc::Server::Start(
        {"127.0.0.1:0"},
        {store_service_.get(), scheduler_service_.get(), objects_service_.get(),
         decomposition_.get(), training_.get(), generation_.get()},
        {"instascene.v1.ContentStore", "instascene.v1.Scheduler", "instascene.v1.Objects",
         "instascene.v1.Decomposition", "instascene.v1.Training", "instascene.v1.Generation"});
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = std::move(*server);
    scene_dir_ = root + "/scene";
    ASSERT_TRUE(WriteClutterScene(*GenerateClutterScene(*ClutterPreset("tiny")), scene_dir_).ok());
  }

  void TearDown() override {
    scheduler_service_->Stop();
    server_->Drain(std::chrono::milliseconds(100));
  }

  std::shared_ptr<grpc::Channel> Channel(const std::string& token) {
    rpc::ChannelOptions options;
    options.token = token;
    return *rpc::Connect(server_->address(), options);
  }
  std::unique_ptr<store_service::RemoteBlobStore> Store(const std::string& token) {
    return std::move(*store_service::RemoteBlobStore::Connect(Channel(token)));
  }
  // Uploads the scene as `token`'s tenant and submits the echo stage for it.
  grpc::Status Submit(const std::string& token, v1::SubmitPipelineResponse* response,
                      bool upload = true, const std::string& parameters_json = "") {
    auto manifest = *store::SceneManifestFromDirectory(scene_dir_);
    store::Digest digest = store::ComputeDigest(store::SerializeManifest(manifest));
    if (upload) digest = store::UploadManifest(*Store(token), manifest, scene_dir_)->manifest;
    v1::SubmitPipelineRequest request;
    rpc::ToProto(digest, request.mutable_scene_manifest());
    request.set_scene("tiny");
    request.add_stages("echo");
    request.set_parameters_json(parameters_json);
    grpc::ClientContext context;
    return v1::Scheduler::NewStub(Channel(token))->SubmitPipeline(&context, request, response);
  }

  instascene::testing::ScopedTempDir temp_{"auth"};
  std::string acme_, beta_, worker_, admin_, scene_dir_;
  std::shared_ptr<auth::Authenticator> auth_;
  std::unique_ptr<store::FilesystemBlobStore> store_;
  std::unique_ptr<scheduler::JobQueue> queue_;
  pipeline::StageRegistry stages_;
  std::unique_ptr<store_service::StoreService> store_service_;
  std::unique_ptr<scheduler::SchedulerService> scheduler_service_;
  std::unique_ptr<objects::ObjectsService> objects_service_;
  std::unique_ptr<decomposition::DecompositionService> decomposition_;
  std::unique_ptr<training::TrainingService> training_;
  std::unique_ptr<generation::GenerationService> generation_;
  std::unique_ptr<rpc::Server> server_;
};

// The status of calling `method` (full name) with an empty request as `token` (generic stub: no
// generated code, so every method of every service is reached the same way).
grpc::StatusCode CallEmpty(const std::shared_ptr<grpc::Channel>& channel,
                           const std::string& method) {
  grpc::GenericStub stub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  grpc::Slice empty("");  // an empty proto message
  grpc::ByteBuffer request(&empty, 1), response;
  std::promise<grpc::Status> done;
  stub.UnaryCall(&context, method, grpc::StubOptions(), &request, &response,
                 [&done](grpc::Status s) { done.set_value(s); });
  return done.get_future().get().error_code();
}

TEST_F(AuthTest, EveryMethodOfEveryServiceRefusesCallsWithoutAValidToken) {
  // Files that define services but no messages are linked only when something names them.
  for (const auto* table : {&descriptor_table_instascene_2fv1_2fdecomposition_2eproto,
                            &descriptor_table_instascene_2fv1_2ftraining_2eproto,
                            &descriptor_table_instascene_2fv1_2fgeneration_2eproto})
    ASSERT_NE(table, nullptr);
  const auto* pool = google::protobuf::DescriptorPool::generated_pool();
  int methods = 0;
  std::string revoked_id, id, secret;
  const std::string revoked = *auth::CreateToken(temp_.Sub("tokens.json"), Role::kAdmin, "", "");
  ASSERT_TRUE(auth::SplitToken(revoked, &revoked_id, &secret).ok());
  ASSERT_TRUE(auth::RevokeToken(temp_.Sub("tokens.json"), revoked_id).ok());
  std::string forged = admin_;
  forged.back() = forged.back() == 'a' ? 'b' : 'a';
  for (const char* name :
       {"ContentStore", "Scheduler", "Objects", "Decomposition", "Training", "Generation"}) {
    const auto* service = pool->FindServiceByName(std::string("instascene.v1.") + name);
    ASSERT_NE(service, nullptr) << name;
    for (int m = 0; m < service->method_count(); ++m, ++methods) {
      const std::string method = "/" + service->full_name() + "/" + service->method(m)->name();
      EXPECT_EQ(CallEmpty(Channel(""), method), grpc::StatusCode::UNAUTHENTICATED) << method;
      EXPECT_EQ(CallEmpty(Channel("isk_nope"), method), grpc::StatusCode::UNAUTHENTICATED)
          << method;
      EXPECT_EQ(CallEmpty(Channel(forged), method), grpc::StatusCode::UNAUTHENTICATED) << method;
    }
  }
  EXPECT_EQ(methods, 28);  // a new method must join this test (and choose its roles)
  // A revoked token is refused (the authenticator re-reads the changed file).
  EXPECT_EQ(CallEmpty(Channel(revoked), "/instascene.v1.Scheduler/GetQueueStats"),
            grpc::StatusCode::UNAUTHENTICATED);
}

TEST_F(AuthTest, RolesLimitWhatATokenMayCall) {
  auto code = [&](const std::string& token, const std::string& method) {
    return CallEmpty(Channel(token), method);
  };
  // Clients: no leasing, completing, monitoring or granting.
  for (const char* m :
       {"/instascene.v1.Scheduler/LeaseJob", "/instascene.v1.Scheduler/CompleteJob",
        "/instascene.v1.Scheduler/FailJob", "/instascene.v1.Scheduler/Heartbeat",
        "/instascene.v1.Scheduler/GetQueueStats", "/instascene.v1.ContentStore/GrantBlobs",
        "/instascene.v1.Training/GetWorkerStatus"})
    EXPECT_EQ(code(acme_, m), grpc::StatusCode::PERMISSION_DENIED) << m;
  // Workers: no submitting, listing, cancelling or monitoring.
  for (const char* m :
       {"/instascene.v1.Scheduler/SubmitPipeline", "/instascene.v1.Scheduler/ListJobs",
        "/instascene.v1.Scheduler/CancelJob", "/instascene.v1.Scheduler/DeleteScene",
        "/instascene.v1.Objects/GetObject", "/instascene.v1.Generation/GetWorkerStatus"})
    EXPECT_EQ(code(worker_, m), grpc::StatusCode::PERMISSION_DENIED) << m;
  // Admins: monitoring works.
  EXPECT_EQ(code(admin_, "/instascene.v1.Scheduler/GetQueueStats"), grpc::StatusCode::OK);
  EXPECT_EQ(code(admin_, "/instascene.v1.Decomposition/GetWorkerStatus"), grpc::StatusCode::OK);
  EXPECT_EQ(code(acme_, "/instascene.v1.Scheduler/ListStages"), grpc::StatusCode::OK);
}

TEST_F(AuthTest, ATenantsUnfinishedJobsAreBoundedOthersAreNot) {
  v1::SubmitPipelineResponse r;
  ASSERT_TRUE(Submit(acme_, &r).ok());
  const std::string other = R"({"echo": {"n": 2}})";  // another job of the same scene
  const grpc::Status over = Submit(acme_, &r, true, other);
  EXPECT_EQ(over.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(over.error_message().find("over its limit of 1"), std::string::npos)
      << over.error_message();
  EXPECT_TRUE(Submit(acme_, &r).ok()) << "resubmitting what it holds adds nothing";
  EXPECT_TRUE(Submit(beta_, &r).ok()) << "another tenant has its own budget";
  EXPECT_TRUE(Submit(admin_, &r, true, other).ok()) << "admins' scenes have no tenant";
  grpc::ClientContext context;
  v1::ListJobsResponse listed;
  ASSERT_TRUE(v1::Scheduler::NewStub(Channel(admin_))
                  ->ListJobs(&context, v1::ListJobsRequest(), &listed)
                  .ok());
  std::multiset<std::string> scenes;
  for (const v1::Job& j : listed.jobs()) scenes.insert(j.scene());
  EXPECT_EQ(scenes, (std::multiset<std::string>{"acme:tiny", "beta:tiny", "tiny"}));
}

TEST_F(AuthTest, ATenantsStoredBytesAreBoundedByItsQuota) {
  v1::SubmitPipelineResponse r;
  ASSERT_TRUE(Submit(acme_, &r).ok());  // the tiny scene: about 1 MB of acme's 8 MiB
  const int64_t held = *store_->TenantBytes("acme");
  ASSERT_GT(held, 0);
  auto acme = Store(acme_);
  const std::string over(static_cast<size_t>(kQuota - held + 1), 'a');  // streamed (Write)
  const absl::Status refused = acme->Put(store::ComputeDigest(over), over);
  EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted) << refused;
  EXPECT_NE(refused.message().find(absl::StrCat("tenant acme holds ", held, " bytes")),
            std::string::npos)
      << refused;
  const std::string fits(static_cast<size_t>(kQuota - held), 'b');  // exactly up to the quota
  EXPECT_TRUE(acme->Put(store::ComputeDigest(fits), fits).ok());
  const absl::Status again = acme->Put(store::ComputeDigest(fits), fits);
  EXPECT_TRUE(again.ok()) << "held already: not counted; " << again;
  const std::string one = "c";  // a batch upload
  EXPECT_EQ(acme->Put(store::ComputeDigest(one), one).code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(*store_->TenantBytes("acme"), kQuota);
  EXPECT_TRUE(Store(beta_)->Put(store::ComputeDigest(over), over).ok())
      << "another tenant has its own quota";
  EXPECT_TRUE(Store(admin_)->Put(store::ComputeDigest(one), one).ok()) << "admins have none";
}

TEST_F(AuthTest, TenantsSeeNothingOfEachOtherAndOutputsAreGrantedToTheirTenant) {
  v1::SubmitPipelineResponse a;
  ASSERT_TRUE(Submit(acme_, &a).ok());
  ASSERT_EQ(a.jobs_size(), 1);
  EXPECT_EQ(a.jobs(0).scene(), "tiny") << "clients see their own names";
  const std::string job = a.jobs(0).id();
  auto beta = v1::Scheduler::NewStub(Channel(beta_));
  auto acme = v1::Scheduler::NewStub(Channel(acme_));
  auto admin = v1::Scheduler::NewStub(Channel(admin_));
  {  // beta cannot see, watch or cancel acme's job or scene
    grpc::ClientContext c1, c2, c3, c4, c5;
    v1::ListJobsResponse listed;
    ASSERT_TRUE(beta->ListJobs(&c1, v1::ListJobsRequest(), &listed).ok());
    EXPECT_EQ(listed.jobs_size(), 0);
    v1::GetJobRequest get;
    get.set_job_id(job);
    v1::Job out;
    EXPECT_EQ(beta->GetJob(&c2, get, &out).error_code(), grpc::StatusCode::NOT_FOUND);
    v1::CancelJobRequest cancel;
    cancel.set_job_id(job);
    EXPECT_EQ(beta->CancelJob(&c3, cancel, &out).error_code(), grpc::StatusCode::NOT_FOUND);
    v1::GetSceneRequest scene;
    scene.set_scene("tiny");
    v1::Scene s;
    EXPECT_EQ(beta->GetScene(&c4, scene, &s).error_code(), grpc::StatusCode::NOT_FOUND);
    v1::WatchJobsRequest watch;
    watch.add_job_ids(job);
    auto reader = beta->WatchJobs(&c5, watch);
    EXPECT_FALSE(reader->Read(&out));
    EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::NOT_FOUND);
  }
  {  // beta cannot submit acme's scene without holding its bytes
    v1::SubmitPipelineResponse b;
    EXPECT_EQ(Submit(beta_, &b, /*upload=*/false).error_code(), grpc::StatusCode::NOT_FOUND);
    // Uploading the same scene gives beta its own job (no shared results, no timing signal).
    ASSERT_TRUE(Submit(beta_, &b).ok());
    EXPECT_TRUE(b.created(0));
    EXPECT_NE(b.jobs(0).id(), job);
  }
  {  // acme lists its job under its name; the admin sees the stored name
    grpc::ClientContext c1, c2;
    v1::ListJobsResponse mine, all;
    ASSERT_TRUE(acme->ListJobs(&c1, v1::ListJobsRequest(), &mine).ok());
    ASSERT_EQ(mine.jobs_size(), 1);
    EXPECT_EQ(mine.jobs(0).scene(), "tiny");
    ASSERT_TRUE(admin->ListJobs(&c2, v1::ListJobsRequest(), &all).ok());
    EXPECT_EQ(all.jobs_size(), 2);
    std::set<std::string> scenes;
    for (const v1::Job& j : all.jobs()) scenes.insert(j.scene());
    EXPECT_EQ(scenes, (std::set<std::string>{"acme:tiny", "beta:tiny"}));
  }
  auto delete_scene = [&](const std::string& token, v1::DeleteSceneResponse* deleted) {
    grpc::ClientContext context;
    v1::DeleteSceneRequest request;
    request.set_scene("tiny");
    return v1::Scheduler::NewStub(Channel(token))->DeleteScene(&context, request, deleted);
  };
  v1::DeleteSceneResponse deleted;
  EXPECT_EQ(delete_scene(acme_, &deleted).error_code(), grpc::StatusCode::FAILED_PRECONDITION)
      << "a scene with a queued job is not deleted";
  // A worker runs acme's job: its output is granted to acme, not to beta.
  auto worker_store = Store(worker_);
  const std::string result = "{\"echo\": true}";
  const store::Digest file = store::ComputeDigest(result);
  ASSERT_TRUE(worker_store->Put(file, result).ok());
  store::Manifest output;
  output.kind = "echo";
  output.files["echo.json"] = file;
  const std::string manifest_bytes = store::SerializeManifest(output);
  const store::Digest manifest = store::ComputeDigest(manifest_bytes);
  ASSERT_TRUE(worker_store->Put(manifest, manifest_bytes).ok());
  auto worker = v1::Scheduler::NewStub(Channel(worker_));
  for (int i = 0; i < 2; ++i) {
    grpc::ClientContext c1, c2;
    v1::LeaseJobRequest lease_request;
    lease_request.set_worker_id("w");
    lease_request.add_kinds("echo");
    v1::LeaseJobResponse lease;
    ASSERT_TRUE(worker->LeaseJob(&c1, lease_request, &lease).ok());
    ASSERT_TRUE(lease.has_job());
    if (lease.job().id() != job) {  // beta's: hand it back failed
      v1::FailJobRequest fail;
      fail.set_job_id(lease.job().id());
      fail.set_lease_token(lease.lease_token());
      fail.set_kind(v1::FAILURE_KIND_PERMANENT);
      v1::FailJobResponse failed;
      ASSERT_TRUE(worker->FailJob(&c2, fail, &failed).ok());
      continue;
    }
    v1::CompleteJobRequest complete;
    complete.set_job_id(job);
    complete.set_lease_token(lease.lease_token());
    rpc::ToProto(manifest, complete.mutable_output_manifest());
    v1::CompleteJobResponse completed;
    ASSERT_TRUE(worker->CompleteJob(&c2, complete, &completed).ok());
  }
  EXPECT_EQ(*Store(acme_)->Read(file), result);
  EXPECT_EQ(*Store(acme_)->Read(manifest), manifest_bytes);
  EXPECT_EQ(Store(beta_)->Read(file).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(Store(beta_)->FindMissing({file, manifest})->size(), 2u);
  // Objects: beta asking for acme's scene reaches the lookup as beta's own (absent) scene.
  auto objects = v1::Objects::NewStub(Channel(beta_));
  grpc::ClientContext c;
  v1::ListObjectsRequest list;
  list.set_scene("tiny");
  v1::ListObjectsResponse listed;
  const grpc::Status s = objects->ListObjects(&c, list, &listed);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(s.error_message().find("beta:tiny"), std::string::npos) << s.error_message();
  // Deleting a scene deletes the caller's own: beta's failed job goes, acme's stays, then goes.
  ASSERT_TRUE(delete_scene(beta_, &deleted).ok());
  EXPECT_EQ(deleted.deleted_jobs(), 1);
  grpc::ClientContext c2;
  v1::ListJobsResponse left;
  ASSERT_TRUE(admin->ListJobs(&c2, v1::ListJobsRequest(), &left).ok());
  ASSERT_EQ(left.jobs_size(), 1);
  EXPECT_EQ(left.jobs(0).scene(), "acme:tiny");
  ASSERT_TRUE(delete_scene(acme_, &deleted).ok());
  EXPECT_EQ(deleted.deleted_jobs(), 1);
  EXPECT_EQ(deleted.kept_jobs(), 0);
  EXPECT_EQ(delete_scene(acme_, &deleted).error_code(), grpc::StatusCode::NOT_FOUND);
}

}  // namespace
}  // namespace instascene
