// Bad requests to the services wired together in one process (services_fixture.h) are refused
// with the right status and leave no trace: earlier data intact, no half-written upload.
#include <gtest/gtest.h>

#include "common/core/testing/files.h"
#include "common/rpc/status.h"
#include "common/store/manifest.h"
#include "services/scheduler/scheduler_service.h"
#include "tests/services_fixture.h"

namespace instascene {
namespace {
using instascene::testing::CountFiles;
using instascene::testing::RandomBytes;
using services_testing::ServicesTest;

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

}  // namespace
}  // namespace instascene
