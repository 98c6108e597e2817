#include "services/scheduler/testing/queue_conformance.h"

#include "common/core/testing/temp_dir.h"
#include "common/store/digest.h"

namespace instascene::scheduler::testing {
namespace {

const std::vector<std::string> kAll = {"decompose", "train", "segment"};

std::optional<Lease> MustLease(JobQueue& q, const std::vector<std::string>& kinds = kAll,
                               const std::string& worker = "w1") {
  auto lease = q.LeaseNext(kinds, worker, 0);
  EXPECT_TRUE(lease.ok()) << lease.status();
  return lease.ok() ? *lease : std::nullopt;
}

}  // namespace

void JobQueueConformanceTest::SetUp() {
  directory_ = instascene::testing::FreshTempDir(
      std::string("queue_") + ::testing::UnitTest::GetInstance()->current_test_info()->name());
  options_.lease_ms = 10000;
  options_.backoff_base_ms = 1000;
  options_.backoff_cap_ms = 4000;
  queue_ = Open();
}

std::unique_ptr<JobQueue> JobQueueConformanceTest::Open() {
  auto q = GetParam().open(directory_, options_, &clock_);
  EXPECT_TRUE(q.ok()) << q.status();
  return q.ok() ? std::move(*q) : nullptr;
}

JobSpec JobQueueConformanceTest::Spec(const std::string& scene, const std::string& kind,
                                      const std::string& depends_on, int priority) {
  JobSpec s;
  s.scene = scene;
  s.kind = kind;
  s.scene_manifest = store::ComputeDigest(scene);
  s.depends_on = depends_on;
  s.priority = priority;
  s.parameters = {{"iterations", 10}};
  return s;
}

TEST_P(JobQueueConformanceTest, SubmitIsIdempotentByKey) {
  auto a = queue_->Submit(Spec("s", "decompose"));
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_TRUE(a->created);
  EXPECT_EQ(a->job.state, JobState::kQueued);
  auto b = queue_->Submit(Spec("s", "decompose"));
  ASSERT_TRUE(b.ok());
  EXPECT_FALSE(b->created);
  EXPECT_EQ(b->job.id, a->job.id);
  JobSpec other = Spec("s", "decompose");
  other.parameters = {{"iterations", 11}};
  EXPECT_NE(queue_->Submit(other)->job.id, a->job.id);
  // A dependent's key includes its dependency's key.
  auto t1 = queue_->Submit(Spec("s", "train", a->job.id));
  auto t2 = queue_->Submit(Spec("s", "train", queue_->Submit(other)->job.id));
  EXPECT_NE(t1->job.id, t2->job.id);
  EXPECT_EQ(queue_->Submit(Spec("s", "train", "jnope")).status().code(),
            absl::StatusCode::kNotFound);
  JobSpec bad = Spec("s", "decompose");
  bad.scene_manifest.hash = "xyz";
  EXPECT_EQ(queue_->Submit(bad).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST_P(JobQueueConformanceTest, LeaseHeartbeatComplete) {
  const std::string id = queue_->Submit(Spec("s", "decompose"))->job.id;
  EXPECT_FALSE(MustLease(*queue_, {"train"}).has_value());  // kind filter
  auto lease = MustLease(*queue_, {"decompose"});
  ASSERT_TRUE(lease.has_value());
  EXPECT_EQ(lease->job.id, id);
  EXPECT_EQ(lease->job.state, JobState::kLeased);
  EXPECT_EQ(lease->job.attempts, 1);
  EXPECT_FALSE(MustLease(*queue_).has_value());  // held jobs are not leased twice
  JobProgress p;
  p.phase = "tracking";
  p.step = 3;
  p.total = 10;
  auto hb = queue_->Heartbeat(id, lease->token, p);
  ASSERT_TRUE(hb.ok()) << hb.status();
  EXPECT_FALSE(hb->cancel_requested);
  EXPECT_EQ(queue_->Get(id)->state, JobState::kRunning);
  EXPECT_EQ(queue_->Get(id)->progress.step, 3);
  // A wrong token is fenced off.
  EXPECT_EQ(queue_->Heartbeat(id, "bogus", p).status().code(),
            absl::StatusCode::kFailedPrecondition);
  const store::Digest out = store::ComputeDigest("output");
  EXPECT_EQ(queue_->Complete(id, "bogus", out).code(), absl::StatusCode::kFailedPrecondition);
  ASSERT_TRUE(queue_->Complete(id, lease->token, out).ok());
  auto done = queue_->Get(id);
  EXPECT_EQ(done->state, JobState::kSucceeded);
  EXPECT_EQ(done->output_manifest, out);
  // Completing twice, or failing after success, is refused.
  EXPECT_FALSE(queue_->Complete(id, lease->token, out).ok());
  EXPECT_FALSE(queue_->Fail(id, lease->token, "x", true, false).ok());
  // Resubmission returns the cached result.
  auto again = queue_->Submit(Spec("s", "decompose"));
  EXPECT_FALSE(again->created);
  EXPECT_EQ(again->job.state, JobState::kSucceeded);
}

TEST_P(JobQueueConformanceTest, DependenciesGateLeasing) {
  const std::string d = queue_->Submit(Spec("s", "decompose"))->job.id;
  const std::string t = queue_->Submit(Spec("s", "train", d))->job.id;
  EXPECT_FALSE(MustLease(*queue_, {"train"}).has_value());
  auto lease = MustLease(*queue_);
  ASSERT_EQ(lease->job.id, d);
  EXPECT_FALSE(MustLease(*queue_).has_value());
  ASSERT_TRUE(queue_->Complete(d, lease->token, store::ComputeDigest("o")).ok());
  auto next = MustLease(*queue_);
  ASSERT_TRUE(next.has_value());
  EXPECT_EQ(next->job.id, t);
}

TEST_P(JobQueueConformanceTest, RetriesWithCappedBackoffThenFails) {
  const std::string d = queue_->Submit(Spec("s", "decompose"))->job.id;
  const std::string t = queue_->Submit(Spec("s", "train", d))->job.id;
  for (int attempt = 1; attempt <= 3; ++attempt) {
    auto lease = MustLease(*queue_);
    ASSERT_TRUE(lease.has_value()) << attempt;
    EXPECT_EQ(lease->job.attempts, attempt);
    ASSERT_TRUE(queue_->Fail(d, lease->token, "disk full", true, false).ok());
    auto job = queue_->Get(d);
    if (attempt < 3) {
      EXPECT_EQ(job->state, JobState::kQueued);
      const int64_t delay = job->not_before_ms - clock_.NowMs();
      const int64_t full = std::min<int64_t>(1000 << (attempt - 1), 4000);
      EXPECT_LE(delay, full);
      EXPECT_GE(delay, static_cast<int64_t>(full * (1 - options_.backoff_jitter)) - 1);
      EXPECT_FALSE(MustLease(*queue_).has_value());  // backing off
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
  // Resubmitting the failed pipeline queues it again from scratch.
  auto again = queue_->Submit(Spec("s", "decompose"));
  EXPECT_EQ(again->job.state, JobState::kQueued);
  EXPECT_EQ(again->job.attempts, 0);
  EXPECT_EQ(queue_->Submit(Spec("s", "train", d))->job.state, JobState::kQueued);
}

TEST_P(JobQueueConformanceTest, ReleaseRequeuesWithoutSpendingAnAttempt) {
  const std::string d = queue_->Submit(Spec("s", "decompose"))->job.id;
  auto lease = MustLease(*queue_);
  ASSERT_TRUE(queue_->Release(d, lease->token, "worker shutting down").ok());
  auto job = queue_->Get(d);
  EXPECT_EQ(job->state, JobState::kQueued);
  EXPECT_EQ(job->attempts, 0);
  EXPECT_EQ(job->error, "worker shutting down");
  EXPECT_EQ(queue_->Release(d, lease->token, "again").code(),
            absl::StatusCode::kFailedPrecondition);
  auto again = MustLease(*queue_);  // no backoff
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(again->job.attempts, 1);
}

TEST_P(JobQueueConformanceTest, NonRetryableFailureFailsAtOnce) {
  const std::string d = queue_->Submit(Spec("s", "decompose"))->job.id;
  auto lease = MustLease(*queue_);
  ASSERT_TRUE(queue_->Fail(d, lease->token, "bad PLY", false, false).ok());
  EXPECT_EQ(queue_->Get(d)->state, JobState::kFailed);
}

TEST_P(JobQueueConformanceTest, ExpiredLeasesAreRescued) {
  const std::string d = queue_->Submit(Spec("s", "decompose"))->job.id;
  auto lease = MustLease(*queue_, kAll, "doomed");
  clock_.Advance(options_.lease_ms - 1);
  EXPECT_EQ(*queue_->RescueExpired(), 0);
  // A heartbeat extends the lease.
  ASSERT_TRUE(queue_->Heartbeat(d, lease->token, {}).ok());
  clock_.Advance(options_.lease_ms - 1);
  EXPECT_EQ(*queue_->RescueExpired(), 0);
  clock_.Advance(2);
  EXPECT_EQ(*queue_->RescueExpired(), 1);
  auto job = queue_->Get(d);
  EXPECT_EQ(job->state, JobState::kQueued);
  EXPECT_NE(job->error.find("doomed"), std::string::npos);
  clock_.Advance(options_.backoff_cap_ms);
  auto second = MustLease(*queue_, kAll, "w2");
  ASSERT_TRUE(second.has_value());
  EXPECT_EQ(second->job.attempts, 2);
  // The first worker comes back: fenced off, its result is not recorded.
  EXPECT_EQ(queue_->Complete(d, lease->token, store::ComputeDigest("stale")).code(),
            absl::StatusCode::kFailedPrecondition);
  ASSERT_TRUE(queue_->Complete(d, second->token, store::ComputeDigest("fresh")).ok());
  EXPECT_EQ(queue_->Get(d)->output_manifest, store::ComputeDigest("fresh"));
}

TEST_P(JobQueueConformanceTest, CancellationReachesQueuedAndRunningJobs) {
  const std::string a = queue_->Submit(Spec("a", "decompose"))->job.id;
  const std::string a2 = queue_->Submit(Spec("a", "train", a))->job.id;
  auto cancelled = queue_->Cancel(a);
  ASSERT_TRUE(cancelled.ok());
  EXPECT_EQ(cancelled->state, JobState::kCancelled);
  EXPECT_EQ(queue_->Get(a2)->state, JobState::kCancelled);
  EXPECT_TRUE(queue_->Cancel(a).ok());  // idempotent

  const std::string b = queue_->Submit(Spec("b", "decompose"))->job.id;
  auto lease = MustLease(*queue_);
  ASSERT_EQ(lease->job.id, b);
  auto requested = queue_->Cancel(b);
  EXPECT_TRUE(requested->cancel_requested);
  EXPECT_EQ(requested->state, JobState::kLeased);
  auto hb = queue_->Heartbeat(b, lease->token, {});
  EXPECT_TRUE(hb->cancel_requested);
  ASSERT_TRUE(queue_->Fail(b, lease->token, "stopped", true, true).ok());
  EXPECT_EQ(queue_->Get(b)->state, JobState::kCancelled);

  // A job that finished cannot be cancelled; unknown ids are NotFound.
  const std::string c = queue_->Submit(Spec("c", "decompose"))->job.id;
  auto lc = MustLease(*queue_);
  ASSERT_TRUE(queue_->Complete(c, lc->token, store::ComputeDigest("o")).ok());
  EXPECT_EQ(queue_->Cancel(c).status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(queue_->Cancel("jmissing").status().code(), absl::StatusCode::kNotFound);
  // Reporting a cancellation nobody asked for is refused.
  const std::string d = queue_->Submit(Spec("d", "decompose"))->job.id;
  auto ld = MustLease(*queue_);
  EXPECT_EQ(queue_->Fail(d, ld->token, "x", true, true).code(),
            absl::StatusCode::kFailedPrecondition);
}

TEST_P(JobQueueConformanceTest, PriorityThenFairnessBetweenScenes) {
  // Scene a submits three independent jobs first, then b and c one each.
  std::vector<std::string> order;
  for (int i = 0; i < 3; ++i) {
    JobSpec s = Spec("a", "decompose");
    s.parameters = {{"i", i}};
    ASSERT_TRUE(queue_->Submit(s).ok());
  }
  ASSERT_TRUE(queue_->Submit(Spec("b", "decompose")).ok());
  ASSERT_TRUE(queue_->Submit(Spec("c", "decompose")).ok());
  ASSERT_TRUE(queue_->Submit(Spec("urgent", "decompose", "", /*priority=*/10)).ok());
  for (int i = 0; i < 6; ++i) {
    auto lease = MustLease(*queue_);
    ASSERT_TRUE(lease.has_value());
    order.push_back(lease->job.scene);
    ASSERT_TRUE(queue_->Complete(lease->job.id, lease->token, store::ComputeDigest("o")).ok());
    clock_.Advance(1);
  }
  // Priority first, then round robin between scenes instead of draining scene a.
  EXPECT_EQ(order, (std::vector<std::string>{"urgent", "a", "b", "c", "a", "a"}));
}

TEST_P(JobQueueConformanceTest, SurvivesReopen) {
  const std::string d = queue_->Submit(Spec("s", "decompose"))->job.id;
  const std::string t = queue_->Submit(Spec("s", "train", d))->job.id;
  auto lease = MustLease(*queue_);
  ASSERT_TRUE(queue_->Heartbeat(d, lease->token, {"tracking", 1, 2, 0, -1, ""}).ok());
  queue_.reset();  // the scheduler process goes away
  queue_ = Open();
  ASSERT_NE(queue_, nullptr);
  auto job = queue_->Get(d);
  ASSERT_TRUE(job.ok());
  EXPECT_EQ(job->state, JobState::kRunning);
  EXPECT_EQ(queue_->Get(t)->state, JobState::kQueued);
  // The worker that held the lease can still finish it...
  ASSERT_TRUE(queue_->Complete(d, lease->token, store::ComputeDigest("o")).ok());
  // ...and the rest of the pipeline proceeds.
  auto next = MustLease(*queue_);
  ASSERT_TRUE(next.has_value());
  EXPECT_EQ(next->job.id, t);
}

TEST_P(JobQueueConformanceTest, ListAndStats) {
  const std::string d = queue_->Submit(Spec("s", "decompose"))->job.id;
  ASSERT_TRUE(queue_->Submit(Spec("s", "train", d)).ok());
  ASSERT_TRUE(queue_->Submit(Spec("u", "decompose")).ok());
  clock_.Advance(500);
  auto all = queue_->List({});
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->size(), 3u);
  JobFilter by_scene;
  by_scene.scene = "s";
  EXPECT_EQ(queue_->List(by_scene)->size(), 2u);
  JobFilter by_ids;
  by_ids.ids = {d};
  EXPECT_EQ((*queue_->List(by_ids))[0].id, d);
  auto stats = queue_->Stats();
  ASSERT_TRUE(stats.ok());
  EXPECT_EQ(stats->scenes, 2);
  EXPECT_EQ(stats->jobs_by_state[0], (std::pair<std::string, int64_t>{"queued", 3}));
  EXPECT_EQ(stats->oldest_queued_age_ms, 500);
}

}  // namespace instascene::scheduler::testing
