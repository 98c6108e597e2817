#include "services/scheduler/testing/queue_conformance.h"

#include <set>

#include "common/store/digest.h"
#include "services/scheduler/testing/conformance_plans.h"

namespace instascene::scheduler::testing {

void JobQueueConformanceTest::SetUp() {
  directory_ = std::make_unique<instascene::testing::ScopedTempDir>(
      std::string("queue_") + ::testing::UnitTest::GetInstance()->current_test_info()->name());
  options_.lease_ms = 10000;
  options_.max_lease_ms = 60000;
  options_.backoff_base_ms = 1000;
  options_.backoff_cap_ms = 4000;
  queue_ = Open();
}

std::unique_ptr<JobQueue> JobQueueConformanceTest::Open() {
  auto store = GetParam().open(directory_->str());
  EXPECT_TRUE(store.ok()) << store.status();
  if (!store.ok()) return nullptr;
  return std::make_unique<JobQueue>(std::move(*store), options_, &clock_);
}

std::map<std::string, std::string> JobQueueConformanceTest::SubmitStages(
    const std::string& scene, const std::vector<PlannedStage>& stages, int priority) {
  SubmitRequest r;
  r.scene = scene;
  r.scene_manifest = Out(scene);
  r.stages = stages;
  r.priority = priority;
  auto results = queue_->Submit(r);
  EXPECT_TRUE(results.ok()) << results.status();
  std::map<std::string, std::string> ids;
  if (results.ok())
    for (const SubmitResult& s : *results) ids[s.job.kind] = s.job.id;
  return ids;
}

std::string JobQueueConformanceTest::SubmitOne(const std::string& scene, const std::string& kind,
                                               const nlohmann::json& parameters, int priority) {
  return SubmitStages(scene, {Stage(kind, {}, parameters)}, priority)[kind];
}

std::optional<Lease> JobQueueConformanceTest::MustLease(const std::vector<std::string>& kinds,
                                                        const std::string& worker,
                                                        int64_t lease_ms) {
  auto lease = queue_->LeaseNext(kinds, worker, lease_ms);
  EXPECT_TRUE(lease.ok()) << lease.status();
  return lease.ok() ? *lease : std::nullopt;
}

TEST_P(JobQueueConformanceTest, SubmitIsIdempotentByKey) {
  auto first = SubmitStages("s", {Stage("decompose"), Stage("train", {{"decompose"}})});
  ASSERT_EQ(first.size(), 2u);
  SubmitRequest again;
  again.scene = "s";
  again.scene_manifest = Out("s");
  again.stages = {Stage("decompose"), Stage("train", {{"decompose"}})};
  auto r = queue_->Submit(again);
  ASSERT_TRUE(r.ok());
  for (const SubmitResult& s : *r) EXPECT_FALSE(s.created) << s.job.kind;
  EXPECT_EQ((*r)[1].job.id, first["train"]);
  EXPECT_EQ((*r)[1].job.dependencies,
            (std::vector<JobDependency>{{"decompose", first["decompose"]}}));
  EXPECT_EQ((*r)[1].job.pending, 1);
  // A changed parameter changes that job and every job depending on it, not the others.
  again.stages[0].parameters = {{"p", 2}};
  auto changed = queue_->Submit(again);
  EXPECT_NE((*changed)[0].job.id, first["decompose"]);
  EXPECT_NE((*changed)[1].job.id, first["train"]);
  again.stages[0].parameters = {{"p", 1}};
  again.stages[1].parameters = {{"p", 3}};
  changed = queue_->Submit(again);
  EXPECT_EQ((*changed)[0].job.id, first["decompose"]);
  EXPECT_FALSE((*changed)[0].created);
  EXPECT_NE((*changed)[1].job.id, first["train"]);
  // Malformed submissions create nothing.
  const int64_t before = queue_->List({})->size();
  SubmitRequest bad = again;
  bad.stages = {Stage("decompose"), Stage("train", {{"missing"}})};
  EXPECT_EQ(queue_->Submit(bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad.stages = {Stage("decompose", {}, {{"p", 9}}), Stage("decompose")};
  EXPECT_EQ(queue_->Submit(bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad.stages = {Stage("decompose", {}, {{"p", 9}}),
                Stage("join", {{"decompose", InputMode::kAll}})};
  EXPECT_EQ(queue_->Submit(bad).status().code(), absl::StatusCode::kInvalidArgument);
  bad = again;
  bad.scene_manifest.hash = "xyz";
  EXPECT_EQ(queue_->Submit(bad).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(static_cast<int64_t>(queue_->List({})->size()), before);
}

TEST_P(JobQueueConformanceTest, LeaseHeartbeatComplete) {
  const std::string id = SubmitOne("s", "decompose");
  EXPECT_FALSE(MustLease({"train"}).has_value());  // kind filter
  auto lease = MustLease({"decompose"});
  ASSERT_TRUE(lease.has_value());
  EXPECT_EQ(lease->job.id, id);
  EXPECT_EQ(lease->job.state, JobState::kLeased);
  EXPECT_EQ(lease->job.attempts, 1);
  EXPECT_TRUE(lease->inputs.empty());
  EXPECT_FALSE(MustLease(kAll).has_value());  // held jobs are not leased twice
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
  EXPECT_EQ(queue_->Complete(id, "bogus", Out("output")).code(),
            absl::StatusCode::kFailedPrecondition);
  ASSERT_TRUE(queue_->Complete(id, lease->token, Out("output")).ok());
  auto done = queue_->Get(id);
  EXPECT_EQ(done->state, JobState::kSucceeded);
  EXPECT_EQ(done->output_manifest, Out("output"));
  // Completing twice, or failing after success, is refused.
  EXPECT_FALSE(queue_->Complete(id, lease->token, Out("output")).ok());
  EXPECT_FALSE(queue_->Fail(id, lease->token, FailureKind::kRetryable, "x").ok());
  // Resubmission returns the cached result.
  SubmitRequest again;
  again.scene = "s";
  again.scene_manifest = Out("s");
  again.stages = {Stage("decompose")};
  auto r = queue_->Submit(again);
  EXPECT_FALSE((*r)[0].created);
  EXPECT_EQ((*r)[0].job.state, JobState::kSucceeded);
}

TEST_P(JobQueueConformanceTest, FanInWaitsForEveryDependencyAndNamesItsInputs) {
  auto ids = SubmitStages(
      "s", {Stage("decompose"), Stage("train"), Stage("segment", {{"decompose"}, {"train"}})});
  EXPECT_FALSE(MustLease({"segment"}).has_value());
  for (const char* kind : {"decompose", "train"}) {
    EXPECT_FALSE(MustLease({"segment"}).has_value()) << kind;
    auto lease = MustLease({kind});
    ASSERT_TRUE(lease.has_value()) << kind;
    ASSERT_TRUE(queue_->Complete(lease->job.id, lease->token, Out(kind)).ok());
  }
  auto lease = MustLease({"segment"});
  ASSERT_TRUE(lease.has_value());
  EXPECT_EQ(lease->job.id, ids["segment"]);
  EXPECT_EQ(lease->inputs, (std::vector<std::pair<std::string, store::Digest>>{
                               {"decompose", Out("decompose")}, {"train", Out("train")}}));
}

TEST_P(JobQueueConformanceTest, PriorityThenFairnessBetweenScenes) {
  // Scene a submits three independent jobs first, then b and c one each.
  for (int i = 0; i < 3; ++i) SubmitOne("a", "decompose", {{"i", i}});
  SubmitOne("b", "decompose");
  SubmitOne("c", "decompose");
  SubmitOne("urgent", "decompose", {{"p", 1}}, /*priority=*/10);
  std::vector<std::string> order;
  for (int i = 0; i < 6; ++i) {
    auto lease = MustLease(kAll);
    ASSERT_TRUE(lease.has_value());
    order.push_back(lease->job.scene);
    ASSERT_TRUE(queue_->Complete(lease->job.id, lease->token, Out("o")).ok());
    clock_.Advance(1);
  }
  // Priority first, then round robin between scenes instead of draining scene a.
  EXPECT_EQ(order, (std::vector<std::string>{"urgent", "a", "b", "c", "a", "a"}));
}

TEST_P(JobQueueConformanceTest, SurvivesReopen) {
  auto ids = SubmitStages("s", FanOutPipeline());
  auto lease = MustLease(kAll);
  ASSERT_TRUE(
      queue_->Heartbeat(ids["decompose"], lease->token, {"tracking", 1, 2, 0, -1, ""}).ok());
  queue_.reset();  // the scheduler process goes away
  queue_ = Open();
  ASSERT_NE(queue_, nullptr);
  auto job = queue_->Get(ids["decompose"]);
  ASSERT_TRUE(job.ok());
  EXPECT_EQ(job->state, JobState::kRunning);
  EXPECT_EQ(job->lease_ms, options_.lease_ms);
  EXPECT_EQ(queue_->Get(ids["train"])->state, JobState::kQueued);
  EXPECT_EQ(queue_->Get(ids["segment"])->plans.size(), 1u);
  // The worker that held the lease can still finish it...
  ASSERT_TRUE(queue_->Complete(ids["decompose"], lease->token, Out("o")).ok());
  // ...and the rest of the pipeline proceeds.
  auto next = MustLease(kAll);
  ASSERT_TRUE(next.has_value());
  EXPECT_EQ(next->job.id, ids["train"]);
}

TEST_P(JobQueueConformanceTest, ListAndStats) {
  SubmitStages("s", {Stage("decompose"), Stage("train", {{"decompose"}})});
  SubmitOne("u", "decompose");
  clock_.Advance(500);
  auto all = queue_->List({});
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->size(), 3u);
  JobFilter by_scene;
  by_scene.scene = "s";
  EXPECT_EQ(queue_->List(by_scene)->size(), 2u);
  // Pages: newest first, each page continuing below the last seq of the previous one.
  JobFilter page;
  page.limit = 2;
  auto first = queue_->List(page);
  ASSERT_EQ(first->size(), 2u);
  page.before_seq = first->back().seq;
  auto second = queue_->List(page);
  ASSERT_EQ(second->size(), 1u);
  EXPECT_EQ((*second)[0].id, (*all)[2].id);
  EXPECT_GT((*first)[1].seq, (*second)[0].seq);
  JobFilter by_ids;
  by_ids.ids = {(*all)[0].id};
  EXPECT_EQ((*queue_->List(by_ids))[0].id, (*all)[0].id);
  auto stats = queue_->Stats();
  ASSERT_TRUE(stats.ok());
  EXPECT_EQ(stats->scenes, 2);
  EXPECT_EQ(stats->jobs_by_state[0], (std::pair<std::string, int64_t>{"queued", 3}));
  EXPECT_EQ(stats->oldest_queued_age_ms, 500);
  // Per stage: two queued decompose jobs, one queued train; ages per stage.
  ASSERT_EQ(stats->jobs_by_stage.size(), 2u);
  EXPECT_EQ(stats->jobs_by_stage[0].stage, "decompose");
  EXPECT_EQ(stats->jobs_by_stage[0].state, "queued");
  EXPECT_EQ(stats->jobs_by_stage[0].jobs, 2);
  EXPECT_EQ(stats->jobs_by_stage[1].stage, "train");
  EXPECT_EQ(stats->jobs_by_stage[1].jobs, 1);
  ASSERT_EQ(stats->oldest_queued_age_ms_by_stage.size(), 2u);
  EXPECT_EQ(stats->oldest_queued_age_ms_by_stage[0],
            (std::pair<std::string, int64_t>{"decompose", 500}));
  auto lease = MustLease({"train", "decompose"});
  ASSERT_TRUE(lease.has_value());
  stats = queue_->Stats();
  int64_t leased = 0;
  for (const auto& s : stats->jobs_by_stage) leased += s.state == "leased" ? s.jobs : 0;
  EXPECT_EQ(leased, 1);
}

TEST_P(JobQueueConformanceTest, TenantsShareNoJobsAndListOnlyTheirScenes) {
  // The same scene content under two tenants' names: separate jobs (the tenant is in the key).
  SubmitRequest r;
  r.scene_manifest = Out("same");
  r.stages = {Stage("decompose")};
  r.scene = "acme:kitchen";
  const auto a = queue_->Submit(r);
  r.scene = "acme-2:kitchen";  // a tenant whose name extends the other's
  const auto b = queue_->Submit(r);
  r.scene = "kitchen";  // an admin's unprefixed scene keeps the key it always had
  const auto c = queue_->Submit(r);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  EXPECT_TRUE((*b)[0].created);
  EXPECT_NE((*a)[0].job.id, (*b)[0].job.id);
  EXPECT_NE((*a)[0].job.id, (*c)[0].job.id);
  EXPECT_EQ((*c)[0].job.key, JobKey(Out("same"), "decompose", {{"p", 1}}, {}, -1));
  JobFilter filter;
  filter.scene_prefix = "acme:";
  auto listed = queue_->List(filter);
  ASSERT_TRUE(listed.ok());
  ASSERT_EQ(listed->size(), 1u);
  EXPECT_EQ((*listed)[0].scene, "acme:kitchen");
  filter.scene_prefix = "acme-2:";
  EXPECT_EQ(queue_->List(filter)->size(), 1u);
  filter.scene_prefix = "beta:";
  EXPECT_TRUE(queue_->List(filter)->empty());
}

TEST_P(JobQueueConformanceTest, ATenantsUnfinishedJobsAreBounded) {
  options_.max_unfinished_per_tenant = 3;
  queue_.reset();  // the store's lock goes with it
  queue_ = Open();
  const std::vector<PlannedStage> two = {Stage("decompose"), Stage("train", {{"decompose"}})};
  auto submit = [&](const std::string& scene, const std::vector<PlannedStage>& stages) {
    SubmitRequest r;
    r.scene = scene;
    r.scene_manifest = Out(scene);
    r.stages = stages;
    return queue_->Submit(r);
  };
  auto acme = [&] {
    JobFilter f;
    f.scene_prefix = "acme:";
    return queue_->List(f).value();
  };
  const auto a = submit("acme:a", two);  // 2 of 3
  ASSERT_TRUE(a.ok()) << a.status();
  const auto over = submit("acme:b", two);  // 4 of 3: refused, nothing of it stored
  EXPECT_EQ(over.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_NE(over.status().message().find("tenant acme would hold 4 unfinished jobs"),
            std::string::npos)
      << over.status();
  EXPECT_EQ(acme().size(), 2u);
  EXPECT_TRUE(submit("acme:a", two).ok());  // what it holds already adds nothing
  // Neither another tenant (one whose name extends acme's) nor an admin's scene counts for acme.
  EXPECT_TRUE(submit("acme-2:b", two).ok());
  EXPECT_TRUE(submit("b", two).ok());
  EXPECT_TRUE(submit("acme:c", {Stage("decompose")}).ok());  // 3 of 3
  EXPECT_EQ(submit("acme:d", {Stage("decompose")}).status().code(),
            absl::StatusCode::kResourceExhausted);
  // Finished jobs do not count: a's two cancelled, b's two fit; a queued again would not.
  ASSERT_TRUE(queue_->Cancel((*a)[0].job.id).ok());
  EXPECT_TRUE(submit("acme:b", two).ok());
  EXPECT_EQ(submit("acme:a", two).status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(queue_->Get((*a)[0].job.id)->state, JobState::kCancelled);  // rolled back
  EXPECT_EQ(acme().size(), 5u);
}

TEST_P(JobQueueConformanceTest, ASceneIsDeletedOnceEveryJobOfItEnded) {
  auto ids = SubmitStages("s", {Stage("decompose"), Stage("train", {{"decompose"}})});
  const std::string other = SubmitOne("u", "decompose");
  auto refused = queue_->DeleteScene("s");
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(refused.status().message().find("2 unfinished jobs"), std::string::npos)
      << refused.status();
  auto lease = MustLease({"decompose"});
  ASSERT_TRUE(queue_->Complete(lease->job.id, lease->token, Out("d")).ok());
  ASSERT_EQ(lease->job.id, ids["decompose"]);  // submitted first
  ASSERT_TRUE(queue_->CancelScene("s").ok());  // train: cancelled at once (queued)
  auto deleted = queue_->DeleteScene("s");
  ASSERT_TRUE(deleted.ok()) << deleted.status();
  EXPECT_EQ(deleted->deleted, 2);
  EXPECT_EQ(deleted->kept, 0);
  EXPECT_EQ(queue_->Get(ids["train"]).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(queue_->Get(other)->state, JobState::kQueued);  // another scene untouched
  EXPECT_EQ(queue_->DeleteScene("s").status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(queue_->DeleteScene("").status().code(), absl::StatusCode::kInvalidArgument);
  // Deleted results are computed again when the pipeline is submitted again, under the same ids.
  EXPECT_EQ(SubmitStages("s", {Stage("decompose"), Stage("train", {{"decompose"}})}), ids);
}

TEST_P(JobQueueConformanceTest, PruningRemovesOldFinishedJobsNothingStillNeeded) {
  auto ids = SubmitStages("s", {Stage("decompose"), Stage("train", {{"decompose"}})});
  auto lease = MustLease({"decompose"});
  ASSERT_TRUE(queue_->Complete(ids["decompose"], lease->token, Out("d")).ok());
  const std::string other = SubmitOne("u", "decompose");
  auto lu = MustLease({"decompose"});
  ASSERT_TRUE(queue_->Fail(other, lu->token, FailureKind::kPermanent, "bad").ok());
  clock_.Advance(10000);
  // decompose is old and finished, but train (queued) still needs it; "u" goes.
  EXPECT_EQ(*queue_->PruneFinished(5000), 1);
  EXPECT_EQ(queue_->Get(other).status().code(), absl::StatusCode::kNotFound);
  EXPECT_TRUE(queue_->Get(ids["decompose"]).ok());
  auto lt = MustLease({"train"});
  ASSERT_TRUE(queue_->Complete(ids["train"], lt->token, Out("t")).ok());
  EXPECT_EQ(*queue_->PruneFinished(5000), 1);  // decompose now; train finished just now stays
  clock_.Advance(10000);
  EXPECT_EQ(*queue_->PruneFinished(5000), 1);
  EXPECT_TRUE(queue_->List({})->empty());
  // A pruned result is recomputed when submitted again, under the same ids.
  auto again = SubmitStages("s", {Stage("decompose"), Stage("train", {{"decompose"}})});
  EXPECT_EQ(again, ids);
  EXPECT_EQ(queue_->Get(ids["decompose"])->state, JobState::kQueued);
  EXPECT_EQ(queue_->PruneFinished(-1).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace instascene::scheduler::testing
