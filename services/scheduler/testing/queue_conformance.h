// services/scheduler/testing/queue_conformance.h: the conformance suite every JobQueue backend
// must pass. A backend's test instantiates it with a factory:
//   INSTANTIATE_TEST_SUITE_P(Sqlite, JobQueueConformanceTest,
//   ::testing::Values(MySqliteFactory()));
// The factory opens (or re-opens: durability) a queue stored under a per-test directory.
#pragma once

#include <gtest/gtest.h>

#include <functional>
#include <memory>
#include <string>

#include "services/scheduler/job_queue.h"
#include "services/scheduler/testing/fake_clock.h"

namespace instascene::scheduler::testing {

struct QueueFactory {
  std::string name;
  std::function<absl::StatusOr<std::unique_ptr<JobQueue>>(
      const std::string& directory, const QueueOptions& options, Clock* clock)>
      open;
};

class JobQueueConformanceTest : public ::testing::TestWithParam<QueueFactory> {
 protected:
  void SetUp() override;
  std::unique_ptr<JobQueue> Open();
  JobSpec Spec(const std::string& scene, const std::string& kind,
               const std::string& depends_on = "", int priority = 0);

  std::string directory_;
  QueueOptions options_;
  FakeClock clock_;
  std::unique_ptr<JobQueue> queue_;
};

}  // namespace instascene::scheduler::testing
