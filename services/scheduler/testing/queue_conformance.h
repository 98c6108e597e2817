// services/scheduler/testing/queue_conformance.h: the conformance suite every storage backend of
// the job queue must pass (library instascene_queue_conformance). A backend's test instantiates it
// with a factory:
//   INSTANTIATE_TEST_SUITE_P(Sqlite, JobQueueConformanceTest, ::testing::Values(MyFactory()));
// The factory opens (or re-opens: durability) a store kept under a per-test directory; the suite
// runs the queue core (job_queue.h) over it with a fake clock.
#pragma once

#include <gtest/gtest.h>

#include <functional>
#include <memory>
#include <string>

#include "common/core/testing/fake_clock.h"
#include "common/core/testing/temp_dir.h"
#include "services/scheduler/job_queue.h"

namespace instascene::scheduler::testing {

struct QueueFactory {
  std::string name;
  std::function<absl::StatusOr<std::unique_ptr<QueueStore>>(const std::string& directory)> open;
};

// Test names show the backend, not the factory's bytes.
inline void PrintTo(const QueueFactory& factory, std::ostream* os) { *os << factory.name; }

class JobQueueConformanceTest : public ::testing::TestWithParam<QueueFactory> {
 protected:
  void SetUp() override;
  std::unique_ptr<JobQueue> Open();
  // Submits stages (kind -> inputs) for `scene` with parameters {"p": tag}; returns job ids by
  // kind.
  std::map<std::string, std::string> SubmitStages(const std::string& scene,
                                                  const std::vector<PlannedStage>& stages,
                                                  int priority = 0);
  std::string SubmitOne(const std::string& scene, const std::string& kind,
                        const nlohmann::json& parameters = {{"p", 1}}, int priority = 0);
  std::optional<Lease> MustLease(const std::vector<std::string>& kinds,
                                 const std::string& worker = "w1", int64_t lease_ms = 0);

  std::unique_ptr<instascene::testing::ScopedTempDir> directory_;
  QueueOptions options_;
  instascene::testing::FakeClock clock_;
  std::unique_ptr<JobQueue> queue_;
};

}  // namespace instascene::scheduler::testing
