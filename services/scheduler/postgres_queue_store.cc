#include "services/scheduler/postgres_queue_store.h"

#include <pqxx/pqxx>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "common/core/status.h"

namespace instascene::scheduler {
namespace {

constexpr int kRetries = 8;  // whole-transaction retries on conflicts between replicas
constexpr int64_t kMigrationLock = 0x1a57a5ce;  // pg_advisory_xact_lock key of the migrations
constexpr int kTenantLock = 0x1a57;  // first key of a tenant's lock (the second: its hash)

constexpr char kColumns[] =
    "id, key, scene, kind, parameters, scene_manifest, parent, item, pending, items, plans, "
    "state, priority, attempts, max_attempts, output, error, worker, lease_token, progress, "
    "cancel_requested, created_ms, updated_ms, not_before_ms, lease_expires_ms, lease_ms";

// Migrations in order; version i + 1 is kMigrations[i].
const char* const kMigrations[] = {
    R"sql(
    CREATE TABLE jobs (
      seq BIGSERIAL PRIMARY KEY,
      id TEXT NOT NULL UNIQUE, key TEXT NOT NULL UNIQUE, scene TEXT NOT NULL, kind TEXT NOT NULL,
      parameters TEXT NOT NULL, scene_manifest TEXT NOT NULL, parent TEXT NOT NULL,
      item BIGINT NOT NULL, pending INTEGER NOT NULL, items BIGINT NOT NULL, plans TEXT NOT NULL,
      state SMALLINT NOT NULL, priority INTEGER NOT NULL, attempts INTEGER NOT NULL,
      max_attempts INTEGER NOT NULL, output TEXT NOT NULL, error TEXT NOT NULL,
      worker TEXT NOT NULL, lease_token TEXT NOT NULL, progress TEXT NOT NULL,
      cancel_requested INTEGER NOT NULL, created_ms BIGINT NOT NULL, updated_ms BIGINT NOT NULL,
      not_before_ms BIGINT NOT NULL, lease_expires_ms BIGINT NOT NULL, lease_ms BIGINT NOT NULL);
    CREATE INDEX jobs_ready ON jobs (scene, priority DESC, seq) WHERE state = 1 AND pending = 0;
    CREATE INDEX jobs_held ON jobs (lease_expires_ms) WHERE state IN (2, 3);
    CREATE INDEX jobs_by_scene ON jobs (scene, seq);
    CREATE TABLE job_dependencies (job_id TEXT NOT NULL, name TEXT NOT NULL,
      dependency_id TEXT NOT NULL, PRIMARY KEY (job_id, name));
    CREATE INDEX dependencies_by_dependency ON job_dependencies (dependency_id);
    CREATE TABLE scenes (scene TEXT PRIMARY KEY, last_lease_ms BIGINT NOT NULL);
    )sql",
};

store::Digest DigestOrEmpty(const std::string& text) {
  if (text.empty()) return {};
  absl::StatusOr<store::Digest> d = store::ParseDigest(text);
  return d.ok() ? *d : store::Digest{};
}
std::string DigestText(const store::Digest& d) { return d.hash.empty() ? "" : d.ToString(); }
int Code(JobState s) { return static_cast<int>(s); }

Job RowToJob(const pqxx::row& r) {
  Job j;
  int c = 0;
  j.id = r[c++].as<std::string>();
  j.key = r[c++].as<std::string>();
  j.scene = r[c++].as<std::string>();
  j.kind = r[c++].as<std::string>();
  j.parameters_json = r[c++].as<std::string>();
  j.scene_manifest = DigestOrEmpty(r[c++].as<std::string>());
  j.parent = r[c++].as<std::string>();
  j.item = r[c++].as<int64_t>();
  j.pending = r[c++].as<int>();
  j.items = r[c++].as<int64_t>();
  j.plans = nlohmann::json::parse(r[c++].as<std::string>(), nullptr, false);
  if (!j.plans.is_array()) j.plans = nlohmann::json::array();
  j.state = static_cast<JobState>(r[c++].as<int>());
  j.priority = r[c++].as<int>();
  j.attempts = r[c++].as<int>();
  j.max_attempts = r[c++].as<int>();
  j.output_manifest = DigestOrEmpty(r[c++].as<std::string>());
  j.error = r[c++].as<std::string>();
  j.worker_id = r[c++].as<std::string>();
  j.lease_token = r[c++].as<std::string>();
  j.progress =
      JobProgress::FromJson(nlohmann::json::parse(r[c++].as<std::string>(), nullptr, false));
  j.cancel_requested = r[c++].as<int>() != 0;
  j.created_ms = r[c++].as<int64_t>();
  j.updated_ms = r[c++].as<int64_t>();
  j.not_before_ms = r[c++].as<int64_t>();
  j.lease_expires_ms = r[c++].as<int64_t>();
  j.lease_ms = r[c++].as<int64_t>();
  j.seq = r[c++].as<int64_t>();
  return j;
}

std::vector<std::string> Ids(const pqxx::result& r) {
  std::vector<std::string> ids;
  ids.reserve(r.size());
  for (const pqxx::row& row : r) ids.push_back(row[0].as<std::string>());
  return ids;
}

// Runs `sql` with every column of `j` as $1..$26 (and `extra` parameters after them).
template <typename... Extra>
pqxx::result ExecWithJob(pqxx::transaction_base& tx, const std::string& sql, const Job& j,
                         Extra&&... extra) {
  return tx.exec_params(
      sql, j.id, j.key, j.scene, j.kind, j.parameters_json, DigestText(j.scene_manifest), j.parent,
      j.item, j.pending, j.items, j.plans.dump(), Code(j.state), j.priority, j.attempts,
      j.max_attempts, DigestText(j.output_manifest), j.error, j.worker_id, j.lease_token,
      j.progress.ToJson().dump(), int{j.cancel_requested}, j.created_ms, j.updated_ms,
      j.not_before_ms, j.lease_expires_ms, j.lease_ms, std::forward<Extra>(extra)...);
}

const std::string& Placeholders() {
  static const std::string marks = [] {
    std::string s;
    for (int i = 1; i <= 26; ++i) absl::StrAppend(&s, i > 1 ? "," : "", "$", i);
    return s;
  }();
  return marks;
}

class PostgresTx final : public QueueTx {
 public:
  PostgresTx(pqxx::transaction_base& tx, bool read_only) : tx_(tx), read_only_(read_only) {}

  absl::StatusOr<std::optional<Job>> Get(const std::string& id) override {
    // A writing transaction locks what it reads: concurrent changes of one job serialise.
    const pqxx::result r =
        tx_.exec_params(absl::StrCat("SELECT ", kColumns, ", seq FROM jobs WHERE id = $1",
                                     read_only_ ? "" : " FOR UPDATE"),
                        id);
    if (r.empty()) return std::optional<Job>();
    Job job = RowToJob(r[0]);
    LoadDependencies(&job);
    return std::optional<Job>(std::move(job));
  }

  absl::Status Insert(const Job& job) override {
    ExecWithJob(tx_,
                absl::StrCat("INSERT INTO jobs (", kColumns, ") VALUES (", Placeholders(), ")"),
                job);  // a duplicate id throws unique_violation: the store retries the transaction
    for (const JobDependency& d : job.dependencies)
      tx_.exec_params(
          "INSERT INTO job_dependencies (job_id, name, dependency_id) VALUES ($1,$2,$3)", job.id,
          d.name, d.job_id);
    return absl::OkStatus();
  }

  absl::Status Update(const Job& job) override {
    const pqxx::result r = ExecWithJob(
        tx_,
        absl::StrCat("UPDATE jobs SET (", kColumns, ") = (", Placeholders(), ") WHERE id = $27"),
        job, job.id);
    if (r.affected_rows() != 1)
      return absl::NotFoundError(absl::StrCat("job ", job.id, " not found"));
    return absl::OkStatus();
  }

  absl::StatusOr<std::vector<std::string>> Dependents(const std::string& id) override {
    return Ids(tx_.exec_params(
        "SELECT job_id FROM job_dependencies WHERE dependency_id = $1 ORDER BY job_id", id));
  }

  absl::StatusOr<std::optional<std::string>> NextReady(const std::vector<std::string>& kinds,
                                                       int64_t now_ms) override {
    std::vector<std::string> quoted;
    for (const std::string& k : kinds) quoted.push_back(tx_.quote(k));  // escaped literals
    const std::string list = absl::StrJoin(quoted, ",");
    // Within one scene the fairness terms are equal, so the best job overall is among each scene's
    // best (priority, then submission order): rank those few instead of every ready job. The pick
    // is then locked with SKIP LOCKED; one another replica holds is excluded and the next tried.
    std::vector<std::string> skipped;
    for (int tries = 0; tries < 16; ++tries) {
      std::vector<std::string> excluded;
      for (const std::string& id : skipped) excluded.push_back(tx_.quote(id));
      const pqxx::result r = tx_.exec_params(
          absl::StrCat(
              "WITH best AS (SELECT DISTINCT ON (scene) id, scene, priority, seq FROM jobs "
              "WHERE state = 1 AND pending = 0 AND not_before_ms <= $1 AND kind IN (",
              list, ")",
              excluded.empty()
                  ? ""
                  : absl::StrCat(" AND id NOT IN (", absl::StrJoin(excluded, ","), ")"),
              " ORDER BY scene, priority DESC, seq ASC), "
              "held AS (SELECT scene, COUNT(*) AS n FROM jobs WHERE state IN (2, 3) "
              "AND scene IN (SELECT scene FROM best) GROUP BY scene) "
              "SELECT b.id FROM best b LEFT JOIN scenes s ON s.scene = b.scene "
              "LEFT JOIN held h ON h.scene = b.scene "
              "ORDER BY b.priority DESC, COALESCE(h.n, 0) ASC, COALESCE(s.last_lease_ms, 0) ASC, "
              "b.seq ASC LIMIT 1"),
          now_ms);
      if (r.empty()) return std::optional<std::string>();
      const std::string id = r[0][0].as<std::string>();
      const pqxx::result locked = tx_.exec_params(
          "SELECT id FROM jobs WHERE id = $1 AND state = 1 AND pending = 0 FOR UPDATE SKIP LOCKED",
          id);
      if (!locked.empty()) return std::optional<std::string>(id);
      skipped.push_back(id);  // another replica is leasing it (or it just changed)
    }
    return std::optional<std::string>();  // heavy contention: the worker polls again
  }

  absl::Status TouchScene(const std::string& scene, int64_t now_ms) override {
    tx_.exec_params(
        "INSERT INTO scenes (scene, last_lease_ms) VALUES ($1, $2) "
        "ON CONFLICT (scene) DO UPDATE SET last_lease_ms = EXCLUDED.last_lease_ms",
        scene, now_ms);
    return absl::OkStatus();
  }

  absl::StatusOr<std::vector<std::string>> Expired(int64_t now_ms) override {
    return Ids(tx_.exec_params(
        "SELECT id FROM jobs WHERE state IN (2, 3) AND lease_expires_ms < $1 ORDER BY seq",
        now_ms));
  }

  absl::StatusOr<std::vector<Job>> List(const JobFilter& filter) override {
    std::vector<Job> jobs;
    if (!filter.ids.empty()) {
      for (const std::string& id : filter.ids) {
        const pqxx::result r =
            tx_.exec_params(absl::StrCat("SELECT ", kColumns, ", seq FROM jobs WHERE id = $1"), id);
        if (r.empty()) return absl::NotFoundError(absl::StrCat("job ", id, " not found"));
        jobs.push_back(RowToJob(r[0]));
      }
    } else {
      const int state = filter.state ? Code(*filter.state) : 0;
      const pqxx::result r = tx_.exec_params(
          absl::StrCat(
              "SELECT ", kColumns,
              ", seq FROM jobs WHERE ($1 = '' OR scene = $1) AND ($2 = 0 OR state = $2) "
              "AND ($3 = 0 OR seq < $3) AND ($5 = '' OR substr(scene, 1, length($5)) = $5) "
              "ORDER BY seq DESC LIMIT $4"),
          filter.scene, state, filter.before_seq, int64_t{filter.limit > 0 ? filter.limit : 100},
          filter.scene_prefix);
      for (const pqxx::row& row : r) jobs.push_back(RowToJob(row));
    }
    for (Job& j : jobs) LoadDependencies(&j);
    return jobs;
  }

  absl::StatusOr<int64_t> CountUnfinished(const std::string& scene_prefix) override {
    // Replicas submit concurrently: the prefix's advisory lock, held to the transaction's end,
    // makes the count see every earlier submission of the tenant committed.
    tx_.exec_params("SELECT pg_advisory_xact_lock($1, hashtext($2))", kTenantLock, scene_prefix);
    const pqxx::result r = tx_.exec_params(
        "SELECT COUNT(*) FROM jobs WHERE state IN ($1, $2, $3) AND "
        "substr(scene, 1, length($4)) = $4",
        Code(JobState::kQueued), Code(JobState::kLeased), Code(JobState::kRunning), scene_prefix);
    return r[0][0].as<int64_t>();
  }

  absl::StatusOr<int> DeleteFinished(int64_t cutoff_ms, const std::string& scene) override {
    const pqxx::result r = tx_.exec_params(
        "WITH doomed AS (SELECT id FROM jobs WHERE state IN (4, 5, 6) AND updated_ms < $1 AND "
        "($2 = '' OR scene = $2) AND NOT "
        "EXISTS (SELECT 1 FROM job_dependencies e JOIN jobs d ON d.id = e.job_id WHERE "
        "e.dependency_id = jobs.id AND d.state IN (1, 2, 3)) FOR UPDATE SKIP LOCKED), "
        "gone AS (DELETE FROM job_dependencies WHERE job_id IN (SELECT id FROM doomed)) "
        "DELETE FROM jobs WHERE id IN (SELECT id FROM doomed)",
        cutoff_ms, scene);
    return static_cast<int>(r.affected_rows());
  }

  absl::StatusOr<QueueStats> Stats(int64_t now_ms) override {
    QueueStats stats;
    std::map<int, int64_t> counts;
    for (const pqxx::row& row : tx_.exec("SELECT state, COUNT(*) FROM jobs GROUP BY state"))
      counts[row[0].as<int>()] = row[1].as<int64_t>();
    for (JobState st : {JobState::kQueued, JobState::kLeased, JobState::kRunning,
                        JobState::kSucceeded, JobState::kFailed, JobState::kCancelled})
      stats.jobs_by_state.emplace_back(JobStateName(st), counts[Code(st)]);
    stats.scenes = tx_.exec("SELECT COUNT(DISTINCT scene) FROM jobs")[0][0].as<int64_t>();
    const pqxx::row oldest = tx_.exec("SELECT MIN(created_ms) FROM jobs WHERE state = 1")[0];
    if (!oldest[0].is_null()) stats.oldest_queued_age_ms = now_ms - oldest[0].as<int64_t>();
    for (const pqxx::row& row : tx_.exec(
             "SELECT kind, state, COUNT(*) FROM jobs GROUP BY kind, state ORDER BY kind, state"))
      stats.jobs_by_stage.push_back({row[0].as<std::string>(),
                                     JobStateName(static_cast<JobState>(row[1].as<int>())),
                                     row[2].as<int64_t>()});
    for (const pqxx::row& row : tx_.exec("SELECT kind, MIN(created_ms) FROM jobs WHERE state = 1 "
                                         "GROUP BY kind ORDER BY kind"))
      stats.oldest_queued_age_ms_by_stage.emplace_back(row[0].as<std::string>(),
                                                       now_ms - row[1].as<int64_t>());
    return stats;
  }

 private:
  void LoadDependencies(Job* job) {
    for (const pqxx::row& row :
         tx_.exec_params("SELECT name, dependency_id FROM job_dependencies WHERE job_id = $1 "
                         "ORDER BY name",
                         job->id))
      job->dependencies.push_back({row[0].as<std::string>(), row[1].as<std::string>()});
  }

  pqxx::transaction_base& tx_;
  bool read_only_;
};

}  // namespace

struct PostgresQueueStore::Connection {
  explicit Connection(const std::string& conninfo) : c(conninfo) {}
  pqxx::connection c;
};

PostgresQueueStore::PostgresQueueStore(std::string conninfo, std::string schema)
    : conninfo_(std::move(conninfo)), schema_(std::move(schema)) {}

PostgresQueueStore::~PostgresQueueStore() = default;

absl::Status PostgresQueueStore::Connect() {
  if (connection_ && connection_->c.is_open()) return absl::OkStatus();
  try {
    connection_ = std::make_unique<Connection>(conninfo_);
    if (!schema_.empty()) {
      pqxx::nontransaction setup(connection_->c);
      setup.exec(absl::StrCat("CREATE SCHEMA IF NOT EXISTS ", setup.quote_name(schema_)));
      setup.exec(absl::StrCat("SET search_path TO ", setup.quote_name(schema_)));
    }
  } catch (const std::exception& e) {
    connection_.reset();
    return absl::UnavailableError(absl::StrCat("postgres: cannot connect: ", e.what()));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::unique_ptr<PostgresQueueStore>> PostgresQueueStore::Open(
    const std::string& conninfo, const std::string& schema) {
  std::unique_ptr<PostgresQueueStore> store(new PostgresQueueStore(conninfo, schema));
  RETURN_IF_ERROR(store->Connect());
  RETURN_IF_ERROR(store->Migrate());
  return store;
}

absl::Status PostgresQueueStore::Migrate() {
  try {
    pqxx::work tx(connection_->c);
    // Replicas starting together take turns; each applies only what is missing.
    tx.exec_params("SELECT pg_advisory_xact_lock($1)", kMigrationLock);
    tx.exec(
        "CREATE TABLE IF NOT EXISTS schema_migrations (version INTEGER PRIMARY KEY, "
        "applied_unix_ms BIGINT NOT NULL)");
    const int have =
        tx.exec("SELECT COALESCE(MAX(version), 0) FROM schema_migrations")[0][0].as<int>();
    const int known = static_cast<int>(std::size(kMigrations));
    if (have > known)
      return absl::FailedPreconditionError(absl::StrCat("postgres: the queue schema is at version ",
                                                        have, "; this build knows up to ", known,
                                                        " (a newer scheduler migrated it)"));
    for (int v = have + 1; v <= known; ++v) {
      tx.exec(kMigrations[v - 1]);
      tx.exec_params(
          "INSERT INTO schema_migrations (version, applied_unix_ms) VALUES "
          "($1, (EXTRACT(EPOCH FROM clock_timestamp()) * 1000)::BIGINT)",
          v);
    }
    tx.commit();
  } catch (const std::exception& e) {
    return absl::UnavailableError(absl::StrCat("postgres: migrating the queue schema: ", e.what()));
  }
  return absl::OkStatus();
}

absl::Status PostgresQueueStore::Transact(bool read_only,
                                          const std::function<absl::Status(QueueTx&)>& body) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (int attempt = 1;; ++attempt) {
    RETURN_IF_ERROR(Connect());
    try {
      absl::Status result;
      if (read_only) {
        pqxx::read_transaction tx(connection_->c);
        PostgresTx q(tx, true);
        result = body(q);
        if (result.ok()) tx.commit();
      } else {
        pqxx::work tx(connection_->c);
        PostgresTx q(tx, false);
        result = body(q);
        if (result.ok()) tx.commit();  // otherwise the destructor rolls back
      }
      return result;
    } catch (const pqxx::transaction_rollback& e) {  // serialisation failure, deadlock
      if (attempt >= kRetries)
        return absl::AbortedError(
            absl::StrCat("postgres: gave up after ", attempt, " conflicting attempts: ", e.what()));
    } catch (const pqxx::unique_violation& e) {  // another replica inserted the same job
      if (attempt >= kRetries)
        return absl::AbortedError(
            absl::StrCat("postgres: gave up after ", attempt, " conflicting attempts: ", e.what()));
    } catch (const pqxx::broken_connection& e) {
      connection_.reset();  // the next transaction reconnects
      return absl::UnavailableError(absl::StrCat("postgres: connection lost: ", e.what()));
    } catch (const std::exception& e) {
      return absl::UnavailableError(absl::StrCat("postgres: ", e.what()));
    }
  }
}

absl::StatusOr<std::unique_ptr<JobQueue>> OpenPostgresJobQueue(const std::string& conninfo,
                                                               const QueueOptions& options,
                                                               Clock* clock) {
  RETURN_IF_ERROR(options.Validate());
  ASSIGN_OR_RETURN(std::unique_ptr<PostgresQueueStore> store, PostgresQueueStore::Open(conninfo));
  return std::make_unique<JobQueue>(std::move(store), options, clock);
}

}  // namespace instascene::scheduler
