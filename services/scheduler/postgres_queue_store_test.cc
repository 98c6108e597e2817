// The PostgreSQL storage backend against the job queue conformance suite, on a real PostgreSQL the
// test starts itself (one server per run of this binary, one schema per test), plus what only a
// shared database has: several scheduler replicas leasing from one queue concurrently.
#include "services/scheduler/postgres_queue_store.h"

#include <gtest/gtest.h>
#include <pqxx/pqxx>

#include <atomic>
#include <set>
#include <thread>

#include "common/core/testing/fake_clock.h"
#include "common/store/digest.h"
#include "services/scheduler/testing/postgres_server.h"
#include "services/scheduler/testing/queue_conformance.h"

namespace instascene::scheduler {
namespace {

testing::PostgresServer* server = nullptr;

class ServerEnvironment : public ::testing::Environment {
 public:
  void SetUp() override {
    auto s = testing::PostgresServer::Start();
    ASSERT_TRUE(s.ok()) << s.status();
    server = s->release();
  }
  void TearDown() override {
    delete server;
    server = nullptr;
  }
};
const auto* const kEnvironment = ::testing::AddGlobalTestEnvironment(new ServerEnvironment);

// One schema per test directory: a fresh, empty queue per test, the same one when reopened.
std::string SchemaFor(const std::string& directory) {
  return "q_" + store::ComputeDigest(directory).hash.substr(0, 16);
}

testing::QueueFactory PostgresFactory() {
  return {"postgres", [](const std::string& dir) -> absl::StatusOr<std::unique_ptr<QueueStore>> {
            if (server == nullptr) return absl::FailedPreconditionError("no PostgreSQL server");
            auto store = PostgresQueueStore::Open(server->conninfo(), SchemaFor(dir));
            if (!store.ok()) return store.status();
            return std::unique_ptr<QueueStore>(std::move(*store));
          }};
}

using testing::JobQueueConformanceTest;
INSTANTIATE_TEST_SUITE_P(Postgres, JobQueueConformanceTest, ::testing::Values(PostgresFactory()),
                         [](const ::testing::TestParamInfo<testing::QueueFactory>& p) {
                           return p.param.name;
                         });

TEST(PostgresQueueStore, ReplicasLeaseEveryJobExactlyOnce) {
  ASSERT_NE(server, nullptr);
  instascene::testing::FakeClock clock;
  QueueOptions options;
  constexpr int kJobs = 120, kReplicas = 3;
  std::vector<std::unique_ptr<JobQueue>> replicas;
  for (int r = 0; r < kReplicas; ++r) {
    auto store = PostgresQueueStore::Open(server->conninfo(), "replicas");
    ASSERT_TRUE(store.ok()) << store.status();
    replicas.push_back(std::make_unique<JobQueue>(std::move(*store), options, &clock));
  }
  // Every replica submits the same pipelines concurrently: one job each, whoever wins.
  std::vector<std::thread> threads;
  for (int r = 0; r < kReplicas; ++r) {
    threads.emplace_back([&, r] {
      for (int i = 0; i < kJobs; ++i) {
        SubmitRequest s;
        s.scene = "scene" + std::to_string(i % 7);
        s.scene_manifest = store::ComputeDigest(std::to_string(i));
        s.stages = {{"decompose", nlohmann::json::object(), {}}};
        EXPECT_TRUE(replicas[r]->Submit(s).ok()) << r;
      }
    });
  }
  for (std::thread& t : threads) t.join();
  threads.clear();
  ASSERT_EQ(replicas[0]->Stats()->jobs_by_state[0].second, kJobs);
  // Two workers per replica lease and complete concurrently; nothing is leased twice.
  std::mutex mutex;
  std::multiset<std::string> leased;
  std::atomic<int> errors{0};
  for (int w = 0; w < 2 * kReplicas; ++w) {
    threads.emplace_back([&, w] {
      JobQueue& q = *replicas[w % kReplicas];
      while (true) {
        auto lease = q.LeaseNext({"decompose"}, "w" + std::to_string(w), 0);
        if (!lease.ok()) {
          ++errors;
          return;
        }
        if (!lease->has_value()) return;
        {
          std::lock_guard<std::mutex> lock(mutex);
          leased.insert((*lease)->job.id);
        }
        if (!q.Complete((*lease)->job.id, (*lease)->token, store::ComputeDigest("out")).ok())
          ++errors;
      }
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(errors.load(), 0);
  EXPECT_EQ(leased.size(), size_t(kJobs));
  EXPECT_EQ(std::set<std::string>(leased.begin(), leased.end()).size(), size_t(kJobs));
  auto stats = replicas[1]->Stats();
  EXPECT_EQ(stats->jobs_by_state[3], (std::pair<std::string, int64_t>{"succeeded", kJobs}));
  // Rescue from two replicas at once: each expired lease is handled once.
  SubmitRequest s;
  s.scene = "late";
  s.scene_manifest = store::ComputeDigest("late");
  s.stages = {{"train", nlohmann::json::object(), {}}};
  ASSERT_TRUE(replicas[0]->Submit(s).ok());
  ASSERT_TRUE(replicas[0]->LeaseNext({"train"}, "doomed", 0)->has_value());
  clock.Advance(options.lease_ms + 1);
  std::atomic<int> rescued{0};
  threads.clear();
  for (int r = 0; r < kReplicas; ++r)
    threads.emplace_back([&, r] { rescued += *replicas[r]->RescueExpired(); });
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(rescued.load(), 1);
}

TEST(PostgresQueueStore, MigratesOnceAndRefusesASchemaFromTheFuture) {
  ASSERT_NE(server, nullptr);
  ASSERT_TRUE(PostgresQueueStore::Open(server->conninfo(), "future").ok());
  ASSERT_TRUE(PostgresQueueStore::Open(server->conninfo(), "future").ok());  // nothing to apply
  {
    pqxx::connection c(server->conninfo());
    pqxx::work tx(c);
    EXPECT_EQ(tx.exec("SELECT COUNT(*) FROM future.schema_migrations")[0][0].as<int>(), 1);
    tx.exec("INSERT INTO future.schema_migrations VALUES (99, 0)");
    tx.commit();
  }
  auto newer = PostgresQueueStore::Open(server->conninfo(), "future");
  EXPECT_EQ(newer.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(newer.status().message().find("version 99"), std::string::npos) << newer.status();
  EXPECT_EQ(PostgresQueueStore::Open("host=/nonexistent port=1 user=x dbname=x").status().code(),
            absl::StatusCode::kUnavailable);
}

}  // namespace
}  // namespace instascene::scheduler
