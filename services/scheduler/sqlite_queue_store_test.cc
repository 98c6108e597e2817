// The SQLite storage backend against the job queue conformance suite, plus what only this backend
// has: the schema migration from version 1, and all-or-nothing submission under I/O failure.
#include "services/scheduler/sqlite_queue_store.h"

#include <gtest/gtest.h>
#include <sqlite3.h>

#include "common/core/testing/fake_clock.h"
#include "common/core/testing/temp_dir.h"
#include "services/scheduler/testing/queue_conformance.h"

namespace instascene::scheduler {
namespace {

testing::QueueFactory SqliteFactory() {
  return {"sqlite", [](const std::string& dir) -> absl::StatusOr<std::unique_ptr<QueueStore>> {
            auto store = SqliteQueueStore::Open(dir + "/jobs.db");
            if (!store.ok()) return store.status();
            return std::unique_ptr<QueueStore>(std::move(*store));
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

// A store whose transactions fail at the n-th insert (an I/O error half way).
class FailingTx final : public QueueTx {
 public:
  FailingTx(QueueTx& inner, int* inserts_left) : inner_(inner), left_(inserts_left) {}
  absl::StatusOr<std::optional<Job>> Get(const std::string& id) override { return inner_.Get(id); }
  absl::Status Insert(const Job& job) override {
    if ((*left_)-- == 0) return absl::UnavailableError("disk I/O error");
    return inner_.Insert(job);
  }
  absl::Status Update(const Job& job) override { return inner_.Update(job); }
  absl::StatusOr<std::vector<std::string>> Dependents(const std::string& id) override {
    return inner_.Dependents(id);
  }
  absl::StatusOr<std::optional<std::string>> NextReady(const std::vector<std::string>& kinds,
                                                       int64_t now) override {
    return inner_.NextReady(kinds, now);
  }
  absl::Status TouchScene(const std::string& scene, int64_t now) override {
    return inner_.TouchScene(scene, now);
  }
  absl::StatusOr<std::vector<std::string>> Expired(int64_t now) override {
    return inner_.Expired(now);
  }
  absl::StatusOr<std::vector<Job>> List(const JobFilter& f) override { return inner_.List(f); }
  absl::StatusOr<int64_t> CountUnfinished(const std::string& prefix) override {
    return inner_.CountUnfinished(prefix);
  }
  absl::StatusOr<int> DeleteFinished(int64_t cutoff, const std::string& scene) override {
    return inner_.DeleteFinished(cutoff, scene);
  }
  absl::StatusOr<QueueStats> Stats(int64_t now) override { return inner_.Stats(now); }

 private:
  QueueTx& inner_;
  int* left_;
};

class FailingStore final : public QueueStore {
 public:
  FailingStore(std::unique_ptr<QueueStore> inner, int inserts)
      : inner_(std::move(inner)), left_(inserts) {}
  absl::Status Transact(bool read_only,
                        const std::function<absl::Status(QueueTx&)>& body) override {
    return inner_->Transact(read_only, [&](QueueTx& tx) {
      FailingTx failing(tx, &left_);
      return body(failing);
    });
  }

 private:
  std::unique_ptr<QueueStore> inner_;
  int left_;
};

TEST(SqliteQueueStore, SubmissionIsOneTransaction) {
  const instascene::testing::ScopedTempDir temp("atomic_submit");
  instascene::testing::FakeClock clock;
  JobQueue queue(std::make_unique<FailingStore>(*SqliteQueueStore::Open(temp.Sub("jobs.db")), 2),
                 QueueOptions{}, &clock);
  SubmitRequest r;
  r.scene = "s";
  r.scene_manifest = store::ComputeDigest("s");
  r.stages = {{"decompose", {{"p", 1}}, {}},
              {"train", {{"p", 1}}, {{"decompose", InputMode::kOne}}},
              {"segment", {{"p", 1}}, {{"train", InputMode::kOne}}}};
  // The third insert fails: nothing of the chain remains.
  EXPECT_EQ(queue.Submit(r).status().code(), absl::StatusCode::kUnavailable);
  EXPECT_TRUE(queue.List({})->empty());
  // The store works again: the whole chain goes in.
  auto ok = queue.Submit(r);
  ASSERT_TRUE(ok.ok()) << ok.status();
  EXPECT_EQ(queue.List({})->size(), 3u);
}

TEST(SqliteQueueStore, OneSchedulerOwnsTheFile) {
  const instascene::testing::ScopedTempDir temp("owner");
  auto first = SqliteQueueStore::Open(temp.Sub("jobs.db"));
  ASSERT_TRUE(first.ok());
  EXPECT_EQ(SqliteQueueStore::Open(temp.Sub("jobs.db")).status().code(),
            absl::StatusCode::kFailedPrecondition);
}

TEST(SqliteQueueStore, MigratesVersionOneDatabases) {
  const instascene::testing::ScopedTempDir temp("migrate");
  const std::string path = temp.Sub("jobs.db");
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
    const char* v1 = R"sql(
      CREATE TABLE jobs (seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT NOT NULL UNIQUE,
        key TEXT NOT NULL UNIQUE, scene TEXT NOT NULL, kind TEXT NOT NULL, parameters TEXT NOT NULL,
        scene_manifest TEXT NOT NULL, depends_on TEXT NOT NULL, state INTEGER NOT NULL,
        priority INTEGER NOT NULL, attempts INTEGER NOT NULL, max_attempts INTEGER NOT NULL,
        output TEXT NOT NULL, error TEXT NOT NULL, worker TEXT NOT NULL, lease_token TEXT NOT NULL,
        progress TEXT NOT NULL, cancel_requested INTEGER NOT NULL, created_ms INTEGER NOT NULL,
        updated_ms INTEGER NOT NULL, not_before_ms INTEGER NOT NULL,
        lease_expires_ms INTEGER NOT NULL);
      CREATE INDEX jobs_by_dependency ON jobs(depends_on);
      CREATE TABLE scenes (scene TEXT PRIMARY KEY, last_lease_ms INTEGER NOT NULL);
      INSERT INTO jobs VALUES (1, 'ja', 'ka', 's', 'decompose', '{}', '', '', 4, 0, 1, 3,
        '', '', '', '', '{}', 0, 1, 1, 0, 0);
      INSERT INTO jobs VALUES (2, 'jb', 'kb', 's', 'train', '{}', '', 'ja', 1, 0, 0, 3,
        '', '', '', '', '{}', 0, 2, 2, 0, 0);
      INSERT INTO jobs VALUES (3, 'jc', 'kc', 's', 'segment', '{}', '', 'jb', 1, 0, 0, 3,
        '', '', '', '', '{}', 0, 3, 3, 0, 0);)sql";
    ASSERT_EQ(sqlite3_exec(db, v1, nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
    sqlite3_close(db);
  }
  instascene::testing::FakeClock clock;
  auto queue = OpenSqliteJobQueue(path, QueueOptions{}, &clock);
  ASSERT_TRUE(queue.ok()) << queue.status();
  EXPECT_EQ((*queue)->Get("jb")->dependencies, (std::vector<JobDependency>{{"decompose", "ja"}}));
  EXPECT_EQ((*queue)->Get("jb")->pending, 0);  // its dependency had succeeded
  EXPECT_EQ((*queue)->Get("jc")->pending, 1);
  auto lease = (*queue)->LeaseNext({"train", "segment"}, "w", 0);
  ASSERT_TRUE(lease.ok()) << lease.status();
  ASSERT_TRUE(lease->has_value());
  EXPECT_EQ((*lease)->job.id, "jb");
  // Opening again is a no-op.
  queue->reset();
  EXPECT_TRUE(OpenSqliteJobQueue(path, QueueOptions{}, &clock).ok());
}

}  // namespace
}  // namespace instascene::scheduler
