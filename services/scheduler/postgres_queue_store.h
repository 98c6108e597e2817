// services/scheduler/postgres_queue_store.h: the scale-out storage backend of the job queue, over
// PostgreSQL (libpqxx). Several scheduler replicas may share one database: the next ready job is
// picked with FOR UPDATE SKIP LOCKED (two replicas never lease one job), every job a writing
// transaction reads is row-locked (SELECT ... FOR UPDATE), so concurrent heartbeats, completions,
// rescues and cancels of one job serialise; a transaction that deadlocks, fails to serialise or
// races another replica's insert of the same job key is retried whole. Ready jobs have a partial
// index. The schema is versioned (schema_migrations) and migrated at start under an advisory lock.
// One connection per store, serialised by a mutex. Thread-safe.
#pragma once

#include <memory>
#include <mutex>
#include <string>

#include "services/scheduler/job_queue.h"

namespace instascene::scheduler {

class PostgresQueueStore final : public QueueStore {
 public:
  // `conninfo`: a libpq connection string or postgres:// URI. `schema`: the PostgreSQL schema the
  // tables live in ("" = the connection's search path); created if missing.
  static absl::StatusOr<std::unique_ptr<PostgresQueueStore>> Open(const std::string& conninfo,
                                                                  const std::string& schema = "");
  ~PostgresQueueStore() override;

  absl::Status Transact(bool read_only, const std::function<absl::Status(QueueTx&)>& body) override;

 private:
  PostgresQueueStore(std::string conninfo, std::string schema);
  // (Re)connects when there is no open connection (at open, and after a lost connection).
  absl::Status Connect();
  absl::Status Migrate();

  struct Connection;  // the pqxx connection (libpqxx stays out of this header)
  const std::string conninfo_, schema_;
  std::unique_ptr<Connection> connection_;
  std::mutex mutex_;
};

// A JobQueue over PostgreSQL (see OpenSqliteJobQueue for the embedded default).
absl::StatusOr<std::unique_ptr<JobQueue>> OpenPostgresJobQueue(const std::string& conninfo,
                                                               const QueueOptions& options,
                                                               Clock* clock = RealClock());

}  // namespace instascene::scheduler
