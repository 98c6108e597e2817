// services/scheduler/queue_uri.h: opens the job queue named by the URI every binary's --queue
// flag takes: sqlite:PATH (the embedded default's DATA/jobs.db) or postgres://HOST[:PORT]/DB
// (also postgresql://; the password from PGPASSWORD or ~/.pgpass, never from the URI's flags).
#pragma once

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "services/scheduler/job_queue.h"

namespace instascene::scheduler {

absl::StatusOr<std::unique_ptr<JobQueue>> OpenJobQueueUri(const std::string& uri,
                                                          const QueueOptions& options);

}  // namespace instascene::scheduler
