#include "services/scheduler/sqlite_queue_store.h"

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "common/core/status.h"
#include "services/scheduler/sqlite_schema.h"
#include "services/scheduler/sqlite_statement.h"

namespace instascene::scheduler {
namespace {

constexpr char kColumns[] =
    "id, key, scene, kind, parameters, scene_manifest, parent, item, pending, items, plans, "
    "state, priority, attempts, max_attempts, output, error, worker, lease_token, progress, "
    "cancel_requested, created_ms, updated_ms, not_before_ms, lease_expires_ms, lease_ms";

absl::Status Exec(sqlite3* db, const std::string& sql) {
  char* error = nullptr;
  if (sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &error) != SQLITE_OK) {
    const std::string why = error ? error : "unknown";
    sqlite3_free(error);
    return absl::UnavailableError(absl::StrCat("sqlite: ", why));
  }
  return absl::OkStatus();
}

store::Digest DigestOrEmpty(const std::string& text) {
  if (text.empty()) return {};
  absl::StatusOr<store::Digest> d = store::ParseDigest(text);
  return d.ok() ? *d : store::Digest{};
}
std::string DigestText(const store::Digest& d) { return d.hash.empty() ? "" : d.ToString(); }
int64_t Code(JobState s) { return static_cast<int64_t>(s); }

Job RowToJob(const Statement& s) {
  Job j;
  int c = 0;
  j.id = s.Text(c++);
  j.key = s.Text(c++);
  j.scene = s.Text(c++);
  j.kind = s.Text(c++);
  j.parameters_json = s.Text(c++);
  j.scene_manifest = DigestOrEmpty(s.Text(c++));
  j.parent = s.Text(c++);
  j.item = s.Int(c++);
  j.pending = static_cast<int>(s.Int(c++));
  j.items = s.Int(c++);
  j.plans = nlohmann::json::parse(s.Text(c++), nullptr, false);
  if (!j.plans.is_array()) j.plans = nlohmann::json::array();
  j.state = static_cast<JobState>(s.Int(c++));
  j.priority = static_cast<int>(s.Int(c++));
  j.attempts = static_cast<int>(s.Int(c++));
  j.max_attempts = static_cast<int>(s.Int(c++));
  j.output_manifest = DigestOrEmpty(s.Text(c++));
  j.error = s.Text(c++);
  j.worker_id = s.Text(c++);
  j.lease_token = s.Text(c++);
  j.progress = JobProgress::FromJson(nlohmann::json::parse(s.Text(c++), nullptr, false));
  j.cancel_requested = s.Int(c++) != 0;
  j.created_ms = s.Int(c++);
  j.updated_ms = s.Int(c++);
  j.not_before_ms = s.Int(c++);
  j.lease_expires_ms = s.Int(c++);
  j.lease_ms = s.Int(c++);
  j.seq = s.Int(c++);
  return j;
}

// Binds every column of kColumns from position `first`.
void BindJob(Statement& s, const Job& j, int first) {
  int i = first;
  s.Bind(i++, j.id);
  s.Bind(i++, j.key);
  s.Bind(i++, j.scene);
  s.Bind(i++, j.kind);
  s.Bind(i++, j.parameters_json);
  s.Bind(i++, DigestText(j.scene_manifest));
  s.Bind(i++, j.parent);
  s.Bind(i++, j.item);
  s.Bind(i++, int64_t{j.pending});
  s.Bind(i++, j.items);
  s.Bind(i++, j.plans.dump());
  s.Bind(i++, Code(j.state));
  s.Bind(i++, int64_t{j.priority});
  s.Bind(i++, int64_t{j.attempts});
  s.Bind(i++, int64_t{j.max_attempts});
  s.Bind(i++, DigestText(j.output_manifest));
  s.Bind(i++, j.error);
  s.Bind(i++, j.worker_id);
  s.Bind(i++, j.lease_token);
  s.Bind(i++, j.progress.ToJson().dump());
  s.Bind(i++, int64_t{j.cancel_requested});
  s.Bind(i++, j.created_ms);
  s.Bind(i++, j.updated_ms);
  s.Bind(i++, j.not_before_ms);
  s.Bind(i++, j.lease_expires_ms);
  s.Bind(i++, j.lease_ms);
}

absl::StatusOr<std::vector<std::string>> Ids(Statement& s) {
  std::vector<std::string> ids;
  while (true) {
    ASSIGN_OR_RETURN(bool row, s.Step());
    if (!row) break;
    ids.push_back(s.Text(0));
  }
  return ids;
}

class SqliteTx final : public QueueTx {
 public:
  explicit SqliteTx(sqlite3* db) : db_(db) {}

  absl::StatusOr<std::optional<Job>> Get(const std::string& id) override {
    Statement s(db_, absl::StrCat("SELECT ", kColumns, ", seq FROM jobs WHERE id = ?"));
    s.Bind(1, id);
    ASSIGN_OR_RETURN(bool row, s.Step());
    if (!row) return std::optional<Job>();
    Job job = RowToJob(s);
    RETURN_IF_ERROR(LoadDependencies(&job));
    return std::optional<Job>(std::move(job));
  }

  absl::Status Insert(const Job& job) override {
    std::vector<std::string> marks(26, "?");
    Statement s(db_, absl::StrCat("INSERT INTO jobs (", kColumns, ") VALUES (",
                                  absl::StrJoin(marks, ","), ")"));
    BindJob(s, job, 1);
    if (absl::StatusOr<bool> r = s.Step(); !r.ok()) {
      if (sqlite3_extended_errcode(db_) == SQLITE_CONSTRAINT_UNIQUE)
        return absl::AlreadyExistsError(absl::StrCat("job ", job.id, " exists"));
      return r.status();
    }
    for (const JobDependency& d : job.dependencies) {
      Statement dep(db_,
                    "INSERT INTO job_dependencies (job_id, name, dependency_id) VALUES (?,?,?)");
      dep.Bind(1, job.id).Bind(2, d.name).Bind(3, d.job_id);
      RETURN_IF_ERROR(dep.Step().status());
    }
    return absl::OkStatus();
  }

  absl::Status Update(const Job& j) override {
    // Every column from the job (the immutable ones are rewritten with their own values).
    std::vector<std::string> marks(26, "?");
    Statement s(db_, absl::StrCat("UPDATE jobs SET (", kColumns, ") = (", absl::StrJoin(marks, ","),
                                  ") WHERE id = ?"));
    BindJob(s, j, 1);
    s.Bind(27, j.id);
    RETURN_IF_ERROR(s.Step().status());
    if (sqlite3_changes(db_) != 1)
      return absl::NotFoundError(absl::StrCat("job ", j.id, " not found"));
    return absl::OkStatus();
  }

  absl::StatusOr<std::vector<std::string>> Dependents(const std::string& id) override {
    Statement s(db_, "SELECT job_id FROM job_dependencies WHERE dependency_id = ? ORDER BY rowid");
    s.Bind(1, id);
    return Ids(s);
  }

  absl::StatusOr<std::optional<std::string>> NextReady(const std::vector<std::string>& kinds,
                                                       int64_t now_ms) override {
    std::vector<std::string> marks(kinds.size(), "?");
    // Held jobs per scene are counted once (not per candidate row): fairness stays O(ready jobs).
    Statement pick(
        db_, absl::StrCat("WITH held AS (SELECT scene, COUNT(*) AS n FROM jobs WHERE state IN "
                          "(?, ?) GROUP BY scene) "
                          "SELECT j.id FROM jobs j LEFT JOIN scenes s ON s.scene = j.scene "
                          "LEFT JOIN held h ON h.scene = j.scene "
                          "WHERE j.state = ? AND j.pending = 0 AND j.not_before_ms <= ? "
                          "AND j.kind IN (",
                          absl::StrJoin(marks, ","),
                          ") ORDER BY j.priority DESC, COALESCE(h.n, 0) ASC, "
                          "COALESCE(s.last_lease_ms, 0) ASC, j.seq ASC LIMIT 1"));
    int i = 1;
    pick.Bind(i++, Code(JobState::kLeased));
    pick.Bind(i++, Code(JobState::kRunning));
    pick.Bind(i++, Code(JobState::kQueued));
    pick.Bind(i++, now_ms);
    for (const std::string& k : kinds) pick.Bind(i++, k);
    ASSIGN_OR_RETURN(bool row, pick.Step());
    if (!row) return std::optional<std::string>();
    return std::optional<std::string>(pick.Text(0));
  }

  absl::Status TouchScene(const std::string& scene, int64_t now_ms) override {
    Statement touch(db_,
                    "INSERT INTO scenes (scene, last_lease_ms) VALUES (?, ?) "
                    "ON CONFLICT(scene) DO UPDATE SET last_lease_ms = excluded.last_lease_ms");
    touch.Bind(1, scene).Bind(2, now_ms);
    return touch.Step().status();
  }

  absl::StatusOr<std::vector<std::string>> Expired(int64_t now_ms) override {
    Statement s(db_, "SELECT id FROM jobs WHERE state IN (?, ?) AND lease_expires_ms < ?");
    s.Bind(1, Code(JobState::kLeased)).Bind(2, Code(JobState::kRunning)).Bind(3, now_ms);
    return Ids(s);
  }

  absl::StatusOr<std::vector<Job>> List(const JobFilter& filter) override {
    std::vector<Job> jobs;
    if (!filter.ids.empty()) {
      for (const std::string& id : filter.ids) {
        ASSIGN_OR_RETURN(std::optional<Job> job, Get(id));
        if (!job) return absl::NotFoundError(absl::StrCat("job ", id, " not found"));
        jobs.push_back(*std::move(job));
      }
      return jobs;
    }
    Statement s(
        db_, absl::StrCat("SELECT ", kColumns,
                          ", seq FROM jobs WHERE (? = '' OR scene = ?) AND (? = 0 OR state = ?) "
                          "AND (? = 0 OR seq < ?) AND (? = '' OR substr(scene, 1, length(?)) = ?) "
                          "ORDER BY seq DESC LIMIT ?"));
    const int64_t state = filter.state ? Code(*filter.state) : 0;
    s.Bind(1, filter.scene).Bind(2, filter.scene).Bind(3, state).Bind(4, state);
    s.Bind(5, filter.before_seq).Bind(6, filter.before_seq);
    s.Bind(7, filter.scene_prefix).Bind(8, filter.scene_prefix).Bind(9, filter.scene_prefix);
    s.Bind(10, int64_t{filter.limit > 0 ? filter.limit : 100});
    while (true) {
      ASSIGN_OR_RETURN(bool row, s.Step());
      if (!row) break;
      jobs.push_back(RowToJob(s));
    }
    for (Job& j : jobs) RETURN_IF_ERROR(LoadDependencies(&j));
    return jobs;
  }

  absl::StatusOr<int64_t> CountUnfinished(const std::string& scene_prefix) override {
    // One writer at a time (SQLite's lock): submissions are counted one after the other.
    Statement s(db_,
                "SELECT COUNT(*) FROM jobs WHERE state IN (?, ?, ?) AND "
                "substr(scene, 1, length(?)) = ?");
    s.Bind(1, Code(JobState::kQueued)).Bind(2, Code(JobState::kLeased));
    s.Bind(3, Code(JobState::kRunning)).Bind(4, scene_prefix).Bind(5, scene_prefix);
    ASSIGN_OR_RETURN(bool row, s.Step());
    if (!row) return absl::InternalError("COUNT(*) returned no row");
    return s.Int(0);
  }

  absl::StatusOr<int> DeleteFinished(int64_t cutoff_ms, const std::string& scene) override {
    Statement pick(db_,
                   "SELECT id FROM jobs WHERE state IN (4, 5, 6) AND updated_ms < ? AND "
                   "(? = '' OR scene = ?) AND NOT EXISTS "
                   "(SELECT 1 FROM job_dependencies e JOIN jobs d ON d.id = e.job_id WHERE "
                   "e.dependency_id = jobs.id AND d.state IN (1, 2, 3))");
    pick.Bind(1, cutoff_ms).Bind(2, scene).Bind(3, scene);
    ASSIGN_OR_RETURN(std::vector<std::string> ids, Ids(pick));
    for (const std::string& id : ids) {
      Statement deps(db_, "DELETE FROM job_dependencies WHERE job_id = ?");
      deps.Bind(1, id);
      RETURN_IF_ERROR(deps.Step().status());
      Statement job(db_, "DELETE FROM jobs WHERE id = ?");
      job.Bind(1, id);
      RETURN_IF_ERROR(job.Step().status());
    }
    return static_cast<int>(ids.size());
  }

  absl::StatusOr<QueueStats> Stats(int64_t now_ms) override {
    QueueStats stats;
    for (JobState st : {JobState::kQueued, JobState::kLeased, JobState::kRunning,
                        JobState::kSucceeded, JobState::kFailed, JobState::kCancelled}) {
      Statement s(db_, "SELECT COUNT(*) FROM jobs WHERE state = ?");
      s.Bind(1, Code(st));
      ASSIGN_OR_RETURN(bool row, s.Step());
      stats.jobs_by_state.emplace_back(JobStateName(st), row ? s.Int(0) : 0);
    }
    Statement scenes(db_, "SELECT COUNT(DISTINCT scene) FROM jobs");
    ASSIGN_OR_RETURN(bool row, scenes.Step());
    stats.scenes = row ? scenes.Int(0) : 0;
    Statement oldest(db_, "SELECT MIN(created_ms) FROM jobs WHERE state = ?");
    oldest.Bind(1, Code(JobState::kQueued));
    ASSIGN_OR_RETURN(row, oldest.Step());
    if (row && oldest.Int(0) > 0) stats.oldest_queued_age_ms = now_ms - oldest.Int(0);
    Statement by_stage(
        db_, "SELECT kind, state, COUNT(*) FROM jobs GROUP BY kind, state ORDER BY kind, state");
    while (true) {
      ASSIGN_OR_RETURN(bool more, by_stage.Step());
      if (!more) break;
      stats.jobs_by_stage.push_back({by_stage.Text(0),
                                     JobStateName(static_cast<JobState>(by_stage.Int(1))),
                                     by_stage.Int(2)});
    }
    Statement oldest_by_stage(
        db_, "SELECT kind, MIN(created_ms) FROM jobs WHERE state = ? GROUP BY kind ORDER BY kind");
    oldest_by_stage.Bind(1, Code(JobState::kQueued));
    while (true) {
      ASSIGN_OR_RETURN(bool more, oldest_by_stage.Step());
      if (!more) break;
      stats.oldest_queued_age_ms_by_stage.emplace_back(oldest_by_stage.Text(0),
                                                       now_ms - oldest_by_stage.Int(1));
    }
    return stats;
  }

 private:
  absl::Status LoadDependencies(Job* job) {
    Statement s(db_,
                "SELECT name, dependency_id FROM job_dependencies WHERE job_id = ? ORDER BY name");
    s.Bind(1, job->id);
    while (true) {
      ASSIGN_OR_RETURN(bool row, s.Step());
      if (!row) break;
      job->dependencies.push_back({s.Text(0), s.Text(1)});
    }
    return absl::OkStatus();
  }

  sqlite3* db_;
};

}  // namespace

SqliteQueueStore::~SqliteQueueStore() { sqlite3_close(db_); }

absl::StatusOr<std::unique_ptr<SqliteQueueStore>> SqliteQueueStore::Open(const std::string& path) {
  ASSIGN_OR_RETURN(FileLock lock, FileLock::Acquire(path + ".lock", "job database " + path));
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(path.c_str(), &db,
                      SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX,
                      nullptr) != SQLITE_OK) {
    const std::string why = db ? sqlite3_errmsg(db) : "out of memory";
    sqlite3_close(db);
    return absl::UnavailableError(absl::StrCat(path, ": cannot open job database: ", why));
  }
  sqlite3_busy_timeout(db, 5000);
  sqlite3_extended_result_codes(db, 1);
  std::unique_ptr<SqliteQueueStore> store(new SqliteQueueStore(db, std::move(lock)));
  RETURN_IF_ERROR(Annotate(Exec(db, "PRAGMA journal_mode=WAL; PRAGMA synchronous=FULL;"), path));
  RETURN_IF_ERROR(store->Migrate(path));
  return store;
}

absl::Status SqliteQueueStore::Migrate(const std::string& path) {
  int64_t current = 0;
  bool has_v1 = false;
  {  // statements finalised before the migration runs (open statements lock their tables)
    Statement version(db_, "PRAGMA user_version");
    ASSIGN_OR_RETURN(bool row, version.Step());
    current = row ? version.Int(0) : 0;
    Statement old(db_, "SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name = 'jobs'");
    ASSIGN_OR_RETURN(row, old.Step());
    has_v1 = row && old.Int(0) > 0;
  }
  if (current == kSqliteSchemaVersion) return absl::OkStatus();
  if (current > kSqliteSchemaVersion)
    return absl::FailedPreconditionError(absl::StrCat(
        path, ": job database has schema version ", current, "; this build knows up to ",
        kSqliteSchemaVersion, " (a newer scheduler wrote it)"));
  const std::string sql = SqliteMigrationSql(has_v1);
  absl::Status s = Exec(db_, sql);
  if (!s.ok()) {
    (void)Exec(db_, "ROLLBACK");
    return Annotate(s, absl::StrCat(path, ": migrating the job database"));
  }
  return absl::OkStatus();
}

absl::Status SqliteQueueStore::Transact(bool read_only,
                                        const std::function<absl::Status(QueueTx&)>& body) {
  std::lock_guard<std::mutex> lock(mutex_);
  RETURN_IF_ERROR(Exec(db_, read_only ? "BEGIN DEFERRED" : "BEGIN IMMEDIATE"));
  SqliteTx tx(db_);
  absl::Status result = body(tx);
  if (!result.ok()) {
    (void)Exec(db_, "ROLLBACK");
    return result;
  }
  if (absl::Status s = Exec(db_, "COMMIT"); !s.ok()) {
    (void)Exec(db_, "ROLLBACK");
    return s;
  }
  return absl::OkStatus();
}

absl::StatusOr<std::unique_ptr<JobQueue>> OpenSqliteJobQueue(const std::string& path,
                                                             const QueueOptions& options,
                                                             Clock* clock) {
  RETURN_IF_ERROR(options.Validate());
  ASSIGN_OR_RETURN(std::unique_ptr<SqliteQueueStore> store, SqliteQueueStore::Open(path));
  return std::make_unique<JobQueue>(std::move(store), options, clock);
}

}  // namespace instascene::scheduler
