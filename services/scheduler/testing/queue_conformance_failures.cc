// The conformance suite's failure cases: retries with backoff, releases, permanent failures,
// bounded and rescued leases, cancellation (queue_conformance.h).
#include "services/scheduler/testing/queue_conformance.h"

#include "services/scheduler/testing/conformance_plans.h"

namespace instascene::scheduler::testing {

TEST_P(JobQueueConformanceTest, RetriesWithCappedBackoffThenFails) {
  auto ids = SubmitStages("s", {Stage("decompose"), Stage("train", {{"decompose"}})});
  const std::string d = ids["decompose"], t = ids["train"];
  for (int attempt = 1; attempt <= 3; ++attempt) {
    auto lease = MustLease(kAll);
    ASSERT_TRUE(lease.has_value()) << attempt;
    EXPECT_EQ(lease->job.attempts, attempt);
    ASSERT_TRUE(queue_->Fail(d, lease->token, FailureKind::kRetryable, "disk full").ok());
    auto job = queue_->Get(d);
    if (attempt < 3) {
      EXPECT_EQ(job->state, JobState::kQueued);
      const int64_t delay = job->not_before_ms - clock_.NowMs();
      const int64_t full = std::min<int64_t>(1000 << (attempt - 1), 4000);
      EXPECT_LE(delay, full);
      EXPECT_GE(delay, static_cast<int64_t>(full * (1 - options_.backoff_jitter)) - 1);
      EXPECT_FALSE(MustLease(kAll).has_value());  // backing off
      clock_.Advance(delay);
    } else {
      EXPECT_EQ(job->state, JobState::kFailed);
      EXPECT_EQ(job->error, "disk full");
    }
  }
  // The dependent can never run: it is cancelled, naming the cause.
  auto dependent = queue_->Get(t);
  EXPECT_EQ(dependent->state, JobState::kCancelled);
  EXPECT_NE(dependent->error.find("disk full"), std::string::npos);
  // Resubmitting the failed pipeline queues both again from scratch, in order.
  auto again = SubmitStages("s", {Stage("decompose"), Stage("train", {{"decompose"}})});
  EXPECT_EQ(queue_->Get(d)->state, JobState::kQueued);
  EXPECT_EQ(queue_->Get(d)->attempts, 0);
  EXPECT_EQ(queue_->Get(t)->state, JobState::kQueued);
  EXPECT_EQ(queue_->Get(t)->pending, 1);
}

TEST_P(JobQueueConformanceTest, ReleaseRequeuesWithoutSpendingAnAttempt) {
  const std::string d = SubmitOne("s", "decompose");
  auto lease = MustLease(kAll);
  ASSERT_TRUE(queue_->Fail(d, lease->token, FailureKind::kReleased, "worker shutting down").ok());
  auto job = queue_->Get(d);
  EXPECT_EQ(job->state, JobState::kQueued);
  EXPECT_EQ(job->attempts, 0);
  EXPECT_EQ(job->error, "worker shutting down");
  EXPECT_EQ(queue_->Fail(d, lease->token, FailureKind::kReleased, "again").code(),
            absl::StatusCode::kFailedPrecondition);
  auto again = MustLease(kAll);  // no backoff
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(again->job.attempts, 1);
}

TEST_P(JobQueueConformanceTest, PermanentFailureFailsAtOnce) {
  const std::string d = SubmitOne("s", "decompose");
  auto lease = MustLease(kAll);
  ASSERT_TRUE(queue_->Fail(d, lease->token, FailureKind::kPermanent, "bad PLY").ok());
  EXPECT_EQ(queue_->Get(d)->state, JobState::kFailed);
  EXPECT_EQ(queue_->Get(d)->attempts, 1);
}

TEST_P(JobQueueConformanceTest, LeasesAreBoundedPersistedAndRescued) {
  const std::string d = SubmitOne("s", "decompose");
  // A worker asking for a lease of decades gets the server's maximum, kept with the job.
  auto lease = MustLease(kAll, "doomed", int64_t{1} << 50);
  ASSERT_TRUE(lease.has_value());
  EXPECT_EQ(lease->job.lease_ms, options_.max_lease_ms);
  EXPECT_EQ(lease->job.lease_expires_ms, clock_.NowMs() + options_.max_lease_ms);
  clock_.Advance(options_.max_lease_ms - 1);
  EXPECT_EQ(*queue_->RescueExpired(), 0);
  // A heartbeat renews with the granted length, not the default.
  auto hb = queue_->Heartbeat(d, lease->token, {});
  ASSERT_TRUE(hb.ok());
  EXPECT_EQ(hb->lease_expires_ms, clock_.NowMs() + options_.max_lease_ms);
  clock_.Advance(options_.max_lease_ms - 1);
  EXPECT_EQ(*queue_->RescueExpired(), 0);
  clock_.Advance(2);
  EXPECT_EQ(*queue_->RescueExpired(), 1);
  auto job = queue_->Get(d);
  EXPECT_EQ(job->state, JobState::kQueued);
  EXPECT_NE(job->error.find("doomed"), std::string::npos);
  clock_.Advance(options_.backoff_cap_ms);
  auto second = MustLease(kAll, "w2", 1);  // too short: the minimum
  ASSERT_TRUE(second.has_value());
  EXPECT_EQ(second->job.attempts, 2);
  EXPECT_EQ(second->job.lease_ms, options_.min_lease_ms);
  // The first worker comes back: fenced off, its result is not recorded.
  EXPECT_EQ(queue_->Complete(d, lease->token, Out("stale")).code(),
            absl::StatusCode::kFailedPrecondition);
  ASSERT_TRUE(queue_->Complete(d, second->token, Out("fresh")).ok());
  EXPECT_EQ(queue_->Get(d)->output_manifest, Out("fresh"));
}

TEST_P(JobQueueConformanceTest, CancellationReachesQueuedAndRunningJobs) {
  auto a = SubmitStages("a", {Stage("decompose"), Stage("train", {{"decompose"}})});
  auto cancelled = queue_->Cancel(a["decompose"]);
  ASSERT_TRUE(cancelled.ok());
  EXPECT_EQ(cancelled->state, JobState::kCancelled);
  EXPECT_EQ(queue_->Get(a["train"])->state, JobState::kCancelled);
  EXPECT_TRUE(queue_->Cancel(a["decompose"]).ok());  // idempotent

  const std::string b = SubmitOne("b", "decompose");
  auto lease = MustLease(kAll);
  ASSERT_EQ(lease->job.id, b);
  auto requested = queue_->Cancel(b);
  EXPECT_TRUE(requested->cancel_requested);
  EXPECT_EQ(requested->state, JobState::kLeased);
  auto hb = queue_->Heartbeat(b, lease->token, {});
  EXPECT_TRUE(hb->cancel_requested);
  ASSERT_TRUE(queue_->Fail(b, lease->token, FailureKind::kCancelled, "stopped").ok());
  EXPECT_EQ(queue_->Get(b)->state, JobState::kCancelled);

  // A job that finished cannot be cancelled; unknown ids are NotFound.
  const std::string c = SubmitOne("c", "decompose");
  auto lc = MustLease(kAll);
  ASSERT_TRUE(queue_->Complete(c, lc->token, Out("o")).ok());
  EXPECT_EQ(queue_->Cancel(c).status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(queue_->Cancel("jmissing").status().code(), absl::StatusCode::kNotFound);
  // Reporting a cancellation nobody asked for is refused.
  const std::string d = SubmitOne("d", "decompose");
  auto ld = MustLease(kAll);
  EXPECT_EQ(queue_->Fail(d, ld->token, FailureKind::kCancelled, "x").code(),
            absl::StatusCode::kFailedPrecondition);
}

}  // namespace instascene::scheduler::testing
