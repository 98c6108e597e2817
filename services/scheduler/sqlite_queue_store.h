// services/scheduler/sqlite_queue_store.h: the embedded storage backend of the job queue: one
// SQLite file in WAL mode with synchronous=FULL, so every acknowledged change survives a crash of
// the process. Writing transactions are BEGIN IMMEDIATE; one connection, serialised by a mutex
// (the scheduler process owns the file; other processes talk to the scheduler over gRPC). The
// schema is versioned (PRAGMA user_version) and migrated at open. Thread-safe.
#pragma once

#include <sqlite3.h>

#include <memory>
#include <mutex>
#include <string>

#include "common/core/file_lock.h"
#include "services/scheduler/job_queue.h"

namespace instascene::scheduler {

class SqliteQueueStore final : public QueueStore {
 public:
  static absl::StatusOr<std::unique_ptr<SqliteQueueStore>> Open(const std::string& path);
  ~SqliteQueueStore() override;

  absl::Status Transact(bool read_only, const std::function<absl::Status(QueueTx&)>& body) override;

 private:
  SqliteQueueStore(sqlite3* db, FileLock lock) : db_(db), lock_(std::move(lock)) {}
  absl::Status Migrate(const std::string& path);

  sqlite3* db_;
  FileLock lock_;  // one scheduler process owns the file
  std::mutex mutex_;
};

// The embedded default: a JobQueue over a SqliteQueueStore at `path`.
absl::StatusOr<std::unique_ptr<JobQueue>> OpenSqliteJobQueue(const std::string& path,
                                                             const QueueOptions& options,
                                                             Clock* clock = RealClock());

}  // namespace instascene::scheduler
