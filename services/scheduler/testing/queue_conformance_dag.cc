// The conformance suite's DAG cases: fan-out, joins and cascades (queue_conformance.h).
#include "services/scheduler/testing/queue_conformance.h"

#include <set>

#include "services/scheduler/testing/conformance_plans.h"

namespace instascene::scheduler::testing {
namespace {

// Runs every leasable job of `kinds` to success; segment reports `items`.
void Drain(JobQueue& q, const std::vector<std::string>& kinds, int64_t items, int* ran = nullptr) {
  while (true) {
    auto lease = q.LeaseNext(kinds, "w", 0);
    ASSERT_TRUE(lease.ok()) << lease.status();
    if (!lease->has_value()) return;
    const Job& job = (*lease)->job;
    ASSERT_TRUE(q.Complete(job.id, (*lease)->token,
                           store::ComputeDigest(job.id + std::to_string(job.item)),
                           job.kind == "segment" ? items : -1)
                    .ok());
    if (ran) ++*ran;
  }
}

}  // namespace

TEST_P(JobQueueConformanceTest, FanOutCreatesOneJobPerItemAndAJoin) {
  auto ids = SubmitStages("s", FanOutPipeline());
  EXPECT_EQ(ids.size(), 3u);  // item and join wait for segment's items
  // Complete decompose and train; segment must report its items.
  Drain(*queue_, {"decompose", "train"}, -1);
  auto seg = MustLease({"segment"});
  ASSERT_TRUE(seg.has_value());
  EXPECT_EQ(queue_->Complete(seg->job.id, seg->token, Out("seg")).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(queue_->Complete(seg->job.id, seg->token, Out("seg"), options_.max_items + 1).code(),
            absl::StatusCode::kInvalidArgument);
  ASSERT_TRUE(queue_->Complete(seg->job.id, seg->token, Out("seg"), 3).ok());
  JobFilter filter;
  filter.scene = "s";
  auto jobs = queue_->List(filter);
  ASSERT_EQ(jobs->size(), 3u + 3u + 1u);
  std::vector<std::string> items;
  std::string join;
  for (const Job& j : *jobs) {
    if (j.kind == "item") {
      EXPECT_EQ(j.parent, ids["segment"]);
      EXPECT_EQ(j.dependencies, (std::vector<JobDependency>{{"decompose", ids["decompose"]},
                                                            {"segment", ids["segment"]}}));
      EXPECT_EQ(j.pending, 0);
      items.push_back(j.id);
    }
    if (j.kind == "join") {
      join = j.id;
      EXPECT_EQ(j.pending, 3);
      EXPECT_EQ(j.dependencies.size(), 3u);
    }
  }
  ASSERT_EQ(items.size(), 3u);
  EXPECT_FALSE(MustLease({"join"}).has_value());
  // The item jobs run (each sees its index), then the join, with every item's output by name.
  std::set<int64_t> seen;
  for (int i = 0; i < 3; ++i) {
    auto lease = MustLease({"item"});
    ASSERT_TRUE(lease.has_value());
    seen.insert(lease->job.item);
    ASSERT_TRUE(
        queue_->Complete(lease->job.id, lease->token, Out(std::to_string(lease->job.item))).ok());
  }
  EXPECT_EQ(seen, (std::set<int64_t>{0, 1, 2}));
  auto lj = MustLease({"join"});
  ASSERT_TRUE(lj.has_value());
  EXPECT_EQ(lj->job.id, join);
  EXPECT_EQ(lj->inputs, (std::vector<std::pair<std::string, store::Digest>>{
                            {"item/0", Out("0")}, {"item/1", Out("1")}, {"item/2", Out("2")}}));
  ASSERT_TRUE(queue_->Complete(join, lj->token, Out("joined")).ok());

  // Resubmission creates nothing and runs nothing.
  const size_t total = queue_->List(filter)->size();
  SubmitRequest again;
  again.scene = "s";
  again.scene_manifest = Out("s");
  again.stages = FanOutPipeline();
  auto r = queue_->Submit(again);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->size(), 3u + 3u + 1u);  // segment succeeded: its children are returned too
  for (const SubmitResult& s : *r) EXPECT_FALSE(s.created) << s.job.kind;
  EXPECT_EQ(queue_->List(filter)->size(), total);
  EXPECT_FALSE(MustLease(kAll).has_value());

  // A changed per-item parameter recomputes exactly the items and the join.
  again.stages = FanOutPipeline({{"p", 2}});
  r = queue_->Submit(again);
  int created = 0;
  for (const SubmitResult& s : *r) {
    created += s.created;
    if (s.created) {
      EXPECT_TRUE(s.job.kind == "item" || s.job.kind == "join") << s.job.kind;
    }
  }
  EXPECT_EQ(created, 4);
  int ran = 0;
  Drain(*queue_, kAll, 3, &ran);
  EXPECT_EQ(ran, 4);

  // The scene: the latest output of each stage, per item for the items.
  auto scene = queue_->GetScene("s");
  ASSERT_TRUE(scene.ok()) << scene.status();
  std::vector<std::pair<std::string, int64_t>> outputs;
  for (const StageOutput& o : scene->outputs) outputs.emplace_back(o.kind, o.item);
  EXPECT_EQ(outputs, (std::vector<std::pair<std::string, int64_t>>{{"decompose", -1},
                                                                   {"item", 0},
                                                                   {"item", 1},
                                                                   {"item", 2},
                                                                   {"join", -1},
                                                                   {"segment", -1},
                                                                   {"train", -1}}));
  for (const StageOutput& o : scene->outputs) {
    if (o.kind == "join") {
      EXPECT_NE(o.job_id, join);  // the newer join
    }
  }
  EXPECT_EQ(queue_->GetScene("nope").status().code(), absl::StatusCode::kNotFound);
}

TEST_P(JobQueueConformanceTest, ZeroItemsRunTheJoinAtOnce) {
  SubmitStages("s", FanOutPipeline());
  Drain(*queue_, {"decompose", "train", "segment"}, 0);
  auto join = MustLease({"join"});
  ASSERT_TRUE(join.has_value());
  EXPECT_TRUE(join->inputs.empty());
  EXPECT_FALSE(MustLease({"item"}).has_value());
}

TEST_P(JobQueueConformanceTest, FailureAndCancellationCascadeThroughTheDag) {
  SubmitStages("s", FanOutPipeline());
  Drain(*queue_, {"decompose", "train", "segment"}, 4);
  // One item fails for good: its siblings go on, the join is cancelled naming the cause.
  auto first = MustLease({"item"});
  ASSERT_TRUE(
      queue_->Fail(first->job.id, first->token, FailureKind::kPermanent, "no surface").ok());
  JobFilter joins;
  joins.scene = "s";
  std::string join;
  const std::vector<Job> listed = *queue_->List(joins);
  for (const Job& j : listed)
    if (j.kind == "join") join = j.id;
  EXPECT_EQ(queue_->Get(join)->state, JobState::kCancelled);
  EXPECT_NE(queue_->Get(join)->error.find("no surface"), std::string::npos);
  // A child retried alone: one item's lease expires; only it runs again.
  auto second = MustLease({"item"});
  clock_.Advance(options_.lease_ms + 1);
  EXPECT_EQ(*queue_->RescueExpired(), 1);
  EXPECT_EQ(queue_->Get(second->job.id)->attempts, 1);
  EXPECT_EQ(queue_->Get(second->job.id)->state, JobState::kQueued);
  // Cancelling the scene cancels every pending child and asks the running one to stop.
  auto running = MustLease({"item"});
  ASSERT_TRUE(running.has_value());
  auto cancelled = queue_->CancelScene("s");
  ASSERT_TRUE(cancelled.ok()) << cancelled.status();
  EXPECT_EQ(cancelled->size(), 3u);  // two queued items (one backing off), the running one
  int queued = 0;
  const std::vector<Job> after = *queue_->List(joins);
  for (const Job& j : after) queued += j.state == JobState::kQueued;
  EXPECT_EQ(queued, 0);
  EXPECT_TRUE(queue_->Get(running->job.id)->cancel_requested);
  EXPECT_FALSE(MustLease(kAll).has_value());
  EXPECT_EQ(queue_->CancelScene("nope").status().code(), absl::StatusCode::kNotFound);
}

TEST_P(JobQueueConformanceTest, APartialJoinRunsOverTheItemsThatSucceeded) {
  options_.partial_join_kinds = {"join"};
  queue_.reset();  // one process owns the queue: close before reopening
  queue_ = Open();
  SubmitStages("s", FanOutPipeline());
  Drain(*queue_, {"decompose", "train", "segment"}, 4);
  // Item 0 succeeds, item 1 fails permanently, item 2 is cancelled, item 3 succeeds.
  std::map<int64_t, Lease> leases;
  for (int i = 0; i < 4; ++i) {
    auto lease = MustLease({"item"});
    ASSERT_TRUE(lease.has_value());
    leases[lease->job.item] = *lease;
  }
  ASSERT_TRUE(queue_->Complete(leases[0].job.id, leases[0].token, Out("0")).ok());
  ASSERT_TRUE(
      queue_->Fail(leases[1].job.id, leases[1].token, FailureKind::kPermanent, "degenerate").ok());
  ASSERT_TRUE(queue_->Cancel(leases[2].job.id).ok());  // running: asked to stop
  ASSERT_TRUE(
      queue_->Fail(leases[2].job.id, leases[2].token, FailureKind::kCancelled, "stopped").ok());
  EXPECT_FALSE(MustLease({"join"}).has_value());  // still waits for item 3
  ASSERT_TRUE(queue_->Complete(leases[3].job.id, leases[3].token, Out("3")).ok());
  auto join = MustLease({"join"});
  ASSERT_TRUE(join.has_value());
  EXPECT_EQ(join->inputs, (std::vector<std::pair<std::string, store::Digest>>{
                              {"item/0", Out("0")}, {"item/3", Out("3")}}));
  ASSERT_TRUE(queue_->Complete(join->job.id, join->token, Out("joined")).ok());
  EXPECT_EQ(queue_->Get(join->job.id)->state, JobState::kSucceeded);

  // Without the option, the same failure cancels the join (the default for joins).
  options_.partial_join_kinds.clear();
  queue_.reset();
  queue_ = Open();
  SubmitStages("t", FanOutPipeline());
  Drain(*queue_, {"decompose", "train", "segment"}, 2);
  auto a = MustLease({"item"});
  ASSERT_TRUE(a.has_value());
  ASSERT_TRUE(queue_->Fail(a->job.id, a->token, FailureKind::kPermanent, "degenerate").ok());
  JobFilter filter;
  filter.scene = "t";
  auto jobs = queue_->List(filter);
  ASSERT_TRUE(jobs.ok());
  int joins = 0;
  for (const Job& j : *jobs) {
    if (j.kind != "join") continue;
    EXPECT_EQ(j.state, JobState::kCancelled);
    ++joins;
  }
  EXPECT_EQ(joins, 1);
}

}  // namespace instascene::scheduler::testing
