// The SQLite backend against the JobQueue conformance suite, plus the pipeline expansion.
#include "services/scheduler/sqlite_job_queue.h"

#include <gtest/gtest.h>

#include "common/core/testing/temp_dir.h"
#include "services/scheduler/submit.h"
#include "services/scheduler/testing/queue_conformance.h"

namespace instascene::scheduler {
namespace {

testing::QueueFactory SqliteFactory() {
  return {"sqlite",
          [](const std::string& dir, const QueueOptions& options,
             Clock* clock) -> absl::StatusOr<std::unique_ptr<JobQueue>> {
            auto q = SqliteJobQueue::Open(dir + "/jobs.db", options, clock);
            if (!q.ok()) return q.status();
            return std::unique_ptr<JobQueue>(std::move(*q));
          }};
}

using testing::JobQueueConformanceTest;
INSTANTIATE_TEST_SUITE_P(Sqlite, JobQueueConformanceTest, ::testing::Values(SqliteFactory()),
                         [](const ::testing::TestParamInfo<testing::QueueFactory>& p) {
                           return p.param.name;
                         });

TEST(TransitionTest, OnlyLegalMoves) {
  EXPECT_EQ(*Transition(JobState::kQueued, JobEvent::kLease), JobState::kLeased);
  EXPECT_EQ(*Transition(JobState::kLeased, JobEvent::kProgress), JobState::kRunning);
  EXPECT_EQ(*Transition(JobState::kRunning, JobEvent::kSucceed), JobState::kSucceeded);
  EXPECT_EQ(*Transition(JobState::kRunning, JobEvent::kRetry), JobState::kQueued);
  EXPECT_EQ(*Transition(JobState::kFailed, JobEvent::kResubmit), JobState::kQueued);
  const auto bad = Transition(JobState::kSucceeded, JobEvent::kLease);
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(bad.status().message(), "cannot lease a succeeded job");
  EXPECT_FALSE(Transition(JobState::kQueued, JobEvent::kSucceed).ok());
  EXPECT_FALSE(Transition(JobState::kSucceeded, JobEvent::kResubmit).ok());
  EXPECT_FALSE(Transition(JobState::kCancelled, JobEvent::kCancel).ok());
}

TEST(SubmitPipelineTest, ChainsStagesAndRefusesBadRequests) {
  testing::FakeClock clock;
  auto queue =
      SqliteJobQueue::Open(instascene::testing::FreshTempDir("submit") + "/jobs.db", {}, &clock);
  ASSERT_TRUE(queue.ok());
  PipelineRequest request;
  request.scene_manifest = store::ComputeDigest("scene");
  request.scene = "kitchen";
  request.parameters = {{"train", {{"iterations", 50}}}};
  auto jobs = SubmitPipeline(**queue, request);
  ASSERT_TRUE(jobs.ok()) << jobs.status();
  ASSERT_EQ(jobs->size(), 3u);
  EXPECT_EQ((*jobs)[1].job.depends_on, (*jobs)[0].job.id);
  EXPECT_EQ((*jobs)[2].job.depends_on, (*jobs)[1].job.id);
  EXPECT_EQ((*jobs)[1].job.parameters_json, R"({"iterations":50})");
  auto again = SubmitPipeline(**queue, request);
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_FALSE((*again)[i].created);
    EXPECT_EQ((*again)[i].job.id, (*jobs)[i].job.id);
  }
  PipelineRequest bad = request;
  bad.parameters = {{"train", {{"iterations", -5}}}};
  EXPECT_EQ(SubmitPipeline(**queue, bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad.parameters = {{"render", nlohmann::json::object()}};
  EXPECT_EQ(SubmitPipeline(**queue, bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = request;
  bad.stages = {"train", "segment"};
  EXPECT_EQ(SubmitPipeline(**queue, bad).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ((*queue)->List({})->size(), 3u);  // nothing queued by the bad requests
}

}  // namespace
}  // namespace instascene::scheduler
