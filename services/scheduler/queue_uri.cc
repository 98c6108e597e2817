#include "services/scheduler/queue_uri.h"

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "services/scheduler/postgres_queue_store.h"
#include "services/scheduler/sqlite_queue_store.h"

namespace instascene::scheduler {

absl::StatusOr<std::unique_ptr<JobQueue>> OpenJobQueueUri(const std::string& uri,
                                                          const QueueOptions& options) {
  if (absl::StartsWith(uri, "sqlite:")) return OpenSqliteJobQueue(uri.substr(7), options);
  if (absl::StartsWith(uri, "postgres://") || absl::StartsWith(uri, "postgresql://"))
    return OpenPostgresJobQueue(uri, options);
  return absl::InvalidArgumentError(absl::StrCat(
      "--queue: expected sqlite:PATH or postgres://..., not '", uri.substr(0, 80), "'"));
}

}  // namespace instascene::scheduler
