#include "services/scheduler/sqlite_job_queue.h"

#include <chrono>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "common/core/status.h"
#include "services/scheduler/sqlite_statement.h"

namespace instascene::scheduler {
namespace {

class RealClockImpl final : public Clock {
 public:
  int64_t NowMs() override {
    return std::chrono::duration_cast<std::chrono::milliseconds>(
               std::chrono::system_clock::now().time_since_epoch())
        .count();
  }
};

constexpr char kColumns[] =
    "id, key, scene, kind, parameters, scene_manifest, depends_on, state, priority, attempts, "
    "max_attempts, output, error, worker, lease_token, progress, cancel_requested, created_ms, "
    "updated_ms, not_before_ms, lease_expires_ms";

store::Digest DigestOrEmpty(const std::string& text) {
  if (text.empty()) return {};
  absl::StatusOr<store::Digest> d = store::ParseDigest(text);
  return d.ok() ? *d : store::Digest{};
}
std::string DigestText(const store::Digest& d) { return d.hash.empty() ? "" : d.ToString(); }

Job RowToJob(const Statement& s) {
  Job j;
  j.id = s.Text(0);
  j.key = s.Text(1);
  j.scene = s.Text(2);
  j.kind = s.Text(3);
  j.parameters_json = s.Text(4);
  j.scene_manifest = DigestOrEmpty(s.Text(5));
  j.depends_on = s.Text(6);
  j.state = static_cast<JobState>(s.Int(7));
  j.priority = static_cast<int>(s.Int(8));
  j.attempts = static_cast<int>(s.Int(9));
  j.max_attempts = static_cast<int>(s.Int(10));
  j.output_manifest = DigestOrEmpty(s.Text(11));
  j.error = s.Text(12);
  j.worker_id = s.Text(13);
  j.lease_token = s.Text(14);
  j.progress = JobProgress::FromJson(nlohmann::json::parse(s.Text(15), nullptr, false));
  j.cancel_requested = s.Int(16) != 0;
  j.created_ms = s.Int(17);
  j.updated_ms = s.Int(18);
  j.not_before_ms = s.Int(19);
  j.lease_expires_ms = s.Int(20);
  return j;
}

int64_t Code(JobState s) { return static_cast<int64_t>(s); }

}  // namespace

Clock* RealClock() {
  static RealClockImpl clock;
  return &clock;
}

absl::Status QueueOptions::Validate() const {
  if (lease_ms <= 0) return absl::InvalidArgumentError("lease_ms must be > 0");
  if (backoff_base_ms < 0 || backoff_cap_ms < backoff_base_ms)
    return absl::InvalidArgumentError("backoff: need 0 <= base <= cap");
  if (backoff_jitter < 0 || backoff_jitter >= 1)
    return absl::InvalidArgumentError("backoff_jitter must be in [0, 1)");
  return absl::OkStatus();
}

SqliteJobQueue::SqliteJobQueue(sqlite3* db, const QueueOptions& options, Clock* clock)
    : db_(db), options_(options), clock_(clock), rng_(options.seed) {}

SqliteJobQueue::~SqliteJobQueue() { sqlite3_close(db_); }

absl::StatusOr<std::unique_ptr<SqliteJobQueue>> SqliteJobQueue::Open(const std::string& path,
                                                                     const QueueOptions& options,
                                                                     Clock* clock) {
  RETURN_IF_ERROR(options.Validate());
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(path.c_str(), &db,
                      SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX,
                      nullptr) != SQLITE_OK) {
    const std::string why = db ? sqlite3_errmsg(db) : "out of memory";
    sqlite3_close(db);
    return absl::UnavailableError(absl::StrCat(path, ": cannot open job database: ", why));
  }
  sqlite3_busy_timeout(db, 5000);
  std::unique_ptr<SqliteJobQueue> queue(new SqliteJobQueue(db, options, clock));
  RETURN_IF_ERROR(Annotate(queue->Exec("PRAGMA journal_mode=WAL; PRAGMA synchronous=FULL;"), path));
  RETURN_IF_ERROR(Annotate(queue->Exec(R"sql(
    CREATE TABLE IF NOT EXISTS jobs (
      seq INTEGER PRIMARY KEY AUTOINCREMENT,
      id TEXT NOT NULL UNIQUE, key TEXT NOT NULL UNIQUE, scene TEXT NOT NULL, kind TEXT NOT NULL,
      parameters TEXT NOT NULL, scene_manifest TEXT NOT NULL, depends_on TEXT NOT NULL,
      state INTEGER NOT NULL, priority INTEGER NOT NULL, attempts INTEGER NOT NULL,
      max_attempts INTEGER NOT NULL, output TEXT NOT NULL, error TEXT NOT NULL,
      worker TEXT NOT NULL, lease_token TEXT NOT NULL, progress TEXT NOT NULL,
      cancel_requested INTEGER NOT NULL, created_ms INTEGER NOT NULL, updated_ms INTEGER NOT NULL,
      not_before_ms INTEGER NOT NULL, lease_expires_ms INTEGER NOT NULL);
    CREATE INDEX IF NOT EXISTS jobs_by_state ON jobs(state, kind);
    CREATE INDEX IF NOT EXISTS jobs_by_scene ON jobs(scene);
    CREATE INDEX IF NOT EXISTS jobs_by_dependency ON jobs(depends_on);
    CREATE TABLE IF NOT EXISTS scenes (scene TEXT PRIMARY KEY, last_lease_ms INTEGER NOT NULL);
  )sql"),
                           path));
  return queue;
}

absl::Status SqliteJobQueue::Exec(const std::string& sql) {
  char* error = nullptr;
  if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &error) != SQLITE_OK) {
    const std::string why = error ? error : "unknown";
    sqlite3_free(error);
    return absl::UnavailableError(absl::StrCat("sqlite: ", why));
  }
  return absl::OkStatus();
}

template <typename Fn>
auto SqliteJobQueue::InTransaction(Fn&& body) -> decltype(body()) {
  std::lock_guard<std::mutex> lock(mutex_);
  RETURN_IF_ERROR(Exec("BEGIN IMMEDIATE"));
  auto result = body();
  if (!result.ok()) {
    (void)Exec("ROLLBACK");
    return result;
  }
  if (absl::Status s = Exec("COMMIT"); !s.ok()) {
    (void)Exec("ROLLBACK");
    return s;
  }
  return result;
}

absl::StatusOr<std::optional<Job>> SqliteJobQueue::Load(const std::string& id) {
  Statement s(db_, absl::StrCat("SELECT ", kColumns, " FROM jobs WHERE id = ?"));
  s.Bind(1, id);
  ASSIGN_OR_RETURN(bool row, s.Step());
  if (!row) return std::optional<Job>();
  return std::optional<Job>(RowToJob(s));
}

absl::Status SqliteJobQueue::Save(const Job& j) {
  Statement s(db_,
              "UPDATE jobs SET state=?, priority=?, attempts=?, output=?, error=?, worker=?, "
              "lease_token=?, progress=?, cancel_requested=?, updated_ms=?, not_before_ms=?, "
              "lease_expires_ms=? WHERE id=?");
  s.Bind(1, Code(j.state))
      .Bind(2, int64_t{j.priority})
      .Bind(3, int64_t{j.attempts})
      .Bind(4, DigestText(j.output_manifest))
      .Bind(5, j.error)
      .Bind(6, j.worker_id)
      .Bind(7, j.lease_token)
      .Bind(8, j.progress.ToJson().dump())
      .Bind(9, int64_t{j.cancel_requested})
      .Bind(10, j.updated_ms)
      .Bind(11, j.not_before_ms)
      .Bind(12, j.lease_expires_ms)
      .Bind(13, j.id);
  return s.Step().status();
}

absl::Status SqliteJobQueue::Apply(Job* job, JobEvent event) {
  absl::StatusOr<JobState> next = Transition(job->state, event);
  if (!next.ok()) return Annotate(next.status(), absl::StrCat("job ", job->id));
  job->state = *next;
  job->updated_ms = clock_->NowMs();
  return absl::OkStatus();
}

absl::StatusOr<SubmitResult> SqliteJobQueue::Submit(const JobSpec& spec) {
  if (spec.kind.empty()) return absl::InvalidArgumentError("job kind is empty");
  RETURN_IF_ERROR(store::ValidateDigest(spec.scene_manifest));
  if (spec.max_attempts < 1) return absl::InvalidArgumentError("max_attempts must be >= 1");
  if (!spec.parameters.is_object())
    return absl::InvalidArgumentError("job parameters must be a JSON object");
  return InTransaction([&]() -> absl::StatusOr<SubmitResult> {
    std::string dependency_key;
    if (!spec.depends_on.empty()) {
      ASSIGN_OR_RETURN(std::optional<Job> parent, Load(spec.depends_on));
      if (!parent)
        return absl::NotFoundError(absl::StrCat("dependency job ", spec.depends_on, " not found"));
      dependency_key = parent->key;
    }
    const std::string key = JobKey(spec, dependency_key);
    const std::string id = JobIdFromKey(key);
    ASSIGN_OR_RETURN(std::optional<Job> existing, Load(id));
    if (existing) {
      if (existing->state == JobState::kFailed || existing->state == JobState::kCancelled) {
        RETURN_IF_ERROR(Apply(&*existing, JobEvent::kResubmit));
        existing->attempts = 0;
        existing->error.clear();
        existing->cancel_requested = false;
        existing->not_before_ms = 0;
        existing->progress = {};
        RETURN_IF_ERROR(Save(*existing));
      }
      return SubmitResult{*existing, false};
    }
    Job j;
    j.id = id;
    j.key = key;
    j.scene = spec.scene;
    j.kind = spec.kind;
    j.parameters_json = spec.parameters.dump();
    j.scene_manifest = spec.scene_manifest;
    j.depends_on = spec.depends_on;
    j.priority = spec.priority;
    j.max_attempts = spec.max_attempts;
    j.created_ms = j.updated_ms = clock_->NowMs();
    Statement s(db_, absl::StrCat("INSERT INTO jobs (", kColumns,
                                  ") VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)"));
    s.Bind(1, j.id).Bind(2, j.key).Bind(3, j.scene).Bind(4, j.kind).Bind(5, j.parameters_json);
    s.Bind(6, j.scene_manifest.ToString()).Bind(7, j.depends_on).Bind(8, Code(j.state));
    s.Bind(9, int64_t{j.priority}).Bind(10, int64_t{0}).Bind(11, int64_t{j.max_attempts});
    s.Bind(12, std::string()).Bind(13, std::string()).Bind(14, std::string());
    s.Bind(15, std::string()).Bind(16, j.progress.ToJson().dump()).Bind(17, int64_t{0});
    s.Bind(18, j.created_ms).Bind(19, j.updated_ms).Bind(20, int64_t{0}).Bind(21, int64_t{0});
    RETURN_IF_ERROR(s.Step().status());
    return SubmitResult{j, true};
  });
}

absl::StatusOr<std::optional<Lease>> SqliteJobQueue::LeaseNext(
    const std::vector<std::string>& kinds, const std::string& worker_id, int64_t lease_ms) {
  if (kinds.empty()) return absl::InvalidArgumentError("lease: no job kinds given");
  if (lease_ms <= 0) lease_ms = options_.lease_ms;
  return InTransaction([&]() -> absl::StatusOr<std::optional<Lease>> {
    const int64_t now = clock_->NowMs();
    std::vector<std::string> marks(kinds.size(), "?");
    // Held jobs per scene are counted once (not per candidate row): fairness stays O(ready jobs).
    Statement pick(
        db_,
        absl::StrCat(
            "WITH held AS (SELECT scene, COUNT(*) AS n FROM jobs WHERE state IN (?, ?) "
            "GROUP BY scene) "
            "SELECT j.id FROM jobs j LEFT JOIN jobs d ON d.id = j.depends_on "
            "LEFT JOIN scenes s ON s.scene = j.scene LEFT JOIN held h ON h.scene = j.scene "
            "WHERE j.state = ? AND j.not_before_ms <= ? AND j.kind IN (",
            absl::StrJoin(marks, ","),
            ") AND (j.depends_on = '' OR d.state = ?) "
            "ORDER BY j.priority DESC, COALESCE(h.n, 0) ASC, COALESCE(s.last_lease_ms, 0) ASC, "
            "j.seq ASC LIMIT 1"));
    int i = 1;
    pick.Bind(i++, Code(JobState::kLeased));
    pick.Bind(i++, Code(JobState::kRunning));
    pick.Bind(i++, Code(JobState::kQueued));
    pick.Bind(i++, now);
    for (const std::string& k : kinds) pick.Bind(i++, k);
    pick.Bind(i++, Code(JobState::kSucceeded));
    ASSIGN_OR_RETURN(bool row, pick.Step());
    if (!row) return std::optional<Lease>();
    ASSIGN_OR_RETURN(std::optional<Job> job, Load(pick.Text(0)));
    RETURN_IF_ERROR(Apply(&*job, JobEvent::kLease));
    ++job->attempts;
    job->worker_id = worker_id;
    job->lease_expires_ms = now + lease_ms;
    job->lease_token = absl::StrCat(job->attempts, "-", rng_() & 0xffffffffffffULL);
    job->progress = {};
    RETURN_IF_ERROR(Save(*job));
    Statement touch(db_,
                    "INSERT INTO scenes (scene, last_lease_ms) VALUES (?, ?) "
                    "ON CONFLICT(scene) DO UPDATE SET last_lease_ms = excluded.last_lease_ms");
    touch.Bind(1, job->scene).Bind(2, now);
    RETURN_IF_ERROR(touch.Step().status());
    return std::optional<Lease>(Lease{*job, job->lease_token});
  });
}

absl::StatusOr<Job> SqliteJobQueue::LoadHeld(const std::string& id, const std::string& token) {
  ASSIGN_OR_RETURN(std::optional<Job> job, Load(id));
  if (!job) return absl::NotFoundError(absl::StrCat("job ", id, " not found"));
  if ((job->state != JobState::kLeased && job->state != JobState::kRunning) ||
      job->lease_token != token)
    return absl::FailedPreconditionError(
        absl::StrCat("job ", id, ": lease lost (job is ", JobStateName(job->state),
                     job->lease_token != token ? ", held under another lease" : "", ")"));
  return *job;
}

absl::StatusOr<HeartbeatResult> SqliteJobQueue::Heartbeat(const std::string& id,
                                                          const std::string& token,
                                                          const JobProgress& progress) {
  return InTransaction([&]() -> absl::StatusOr<HeartbeatResult> {
    ASSIGN_OR_RETURN(Job job, LoadHeld(id, token));
    RETURN_IF_ERROR(Apply(&job, JobEvent::kProgress));
    job.progress = progress;
    job.lease_expires_ms = clock_->NowMs() + options_.lease_ms;
    RETURN_IF_ERROR(Save(job));
    return HeartbeatResult{job.cancel_requested, job.lease_expires_ms};
  });
}

absl::Status SqliteJobQueue::Complete(const std::string& id, const std::string& token,
                                      const store::Digest& output) {
  RETURN_IF_ERROR(store::ValidateDigest(output));
  return InTransaction([&]() -> absl::Status {
    ASSIGN_OR_RETURN(Job job, LoadHeld(id, token));
    RETURN_IF_ERROR(Apply(&job, JobEvent::kSucceed));
    job.output_manifest = output;
    job.lease_token.clear();
    job.error.clear();
    return Save(job);
  });
}

int64_t SqliteJobQueue::BackoffMs(int attempts) {
  const double raw =
      static_cast<double>(options_.backoff_base_ms) * std::pow(2.0, std::max(0, attempts - 1));
  const double capped = std::min(raw, static_cast<double>(options_.backoff_cap_ms));
  const double u = std::uniform_real_distribution<double>(0.0, 1.0)(rng_);
  return static_cast<int64_t>(capped * (1.0 - options_.backoff_jitter * u));
}

absl::Status SqliteJobQueue::CancelDependents(const std::string& id, const std::string& why) {
  Statement s(db_, "SELECT id FROM jobs WHERE depends_on = ? AND state IN (?, ?, ?)");
  s.Bind(1, id)
      .Bind(2, Code(JobState::kQueued))
      .Bind(3, Code(JobState::kLeased))
      .Bind(4, Code(JobState::kRunning));
  std::vector<std::string> children;
  while (true) {
    ASSIGN_OR_RETURN(bool row, s.Step());
    if (!row) break;
    children.push_back(s.Text(0));
  }
  for (const std::string& child : children) {
    ASSIGN_OR_RETURN(std::optional<Job> job, Load(child));
    if (job->state == JobState::kQueued) {
      RETURN_IF_ERROR(Apply(&*job, JobEvent::kCancel));
      job->error = why;
      RETURN_IF_ERROR(Save(*job));
      RETURN_IF_ERROR(CancelDependents(child, why));
    } else {
      job->cancel_requested = true;  // a held dependent cannot exist (it waits for success)
      RETURN_IF_ERROR(Save(*job));
    }
  }
  return absl::OkStatus();
}

absl::Status SqliteJobQueue::RetryOrFail(Job* job, const std::string& error, bool retryable) {
  job->error = error;
  job->lease_token.clear();
  job->lease_expires_ms = 0;
  if (job->cancel_requested) {
    RETURN_IF_ERROR(Apply(job, JobEvent::kCancel));
    RETURN_IF_ERROR(Save(*job));
    return CancelDependents(job->id, absl::StrCat("dependency ", job->id, " was cancelled"));
  }
  if (retryable && job->attempts < job->max_attempts) {
    RETURN_IF_ERROR(Apply(job, JobEvent::kRetry));
    job->not_before_ms = clock_->NowMs() + BackoffMs(job->attempts);
    return Save(*job);
  }
  RETURN_IF_ERROR(Apply(job, JobEvent::kGiveUp));
  RETURN_IF_ERROR(Save(*job));
  return CancelDependents(job->id, absl::StrCat("dependency ", job->id, " failed: ", error));
}

absl::Status SqliteJobQueue::Fail(const std::string& id, const std::string& token,
                                  const std::string& error, bool retryable, bool cancelled) {
  return InTransaction([&]() -> absl::Status {
    ASSIGN_OR_RETURN(Job job, LoadHeld(id, token));
    if (cancelled && !job.cancel_requested)
      return absl::FailedPreconditionError(
          absl::StrCat("job ", id, ": reported cancelled but no cancellation was requested"));
    return RetryOrFail(&job, error, retryable);
  });
}

absl::Status SqliteJobQueue::Release(const std::string& id, const std::string& token,
                                     const std::string& reason) {
  return InTransaction([&]() -> absl::Status {
    ASSIGN_OR_RETURN(Job job, LoadHeld(id, token));
    if (job.cancel_requested) return RetryOrFail(&job, reason, false);  // it ends cancelled
    RETURN_IF_ERROR(Apply(&job, JobEvent::kRetry));
    job.attempts = std::max(0, job.attempts - 1);
    job.error = reason;
    job.lease_token.clear();
    job.lease_expires_ms = 0;
    job.not_before_ms = 0;
    return Save(job);
  });
}

absl::StatusOr<Job> SqliteJobQueue::Cancel(const std::string& id) {
  return InTransaction([&]() -> absl::StatusOr<Job> {
    ASSIGN_OR_RETURN(std::optional<Job> job, Load(id));
    if (!job) return absl::NotFoundError(absl::StrCat("job ", id, " not found"));
    if (job->state == JobState::kCancelled) return *job;
    if (IsFinal(job->state))
      return absl::FailedPreconditionError(
          absl::StrCat("job ", id, " is already ", JobStateName(job->state)));
    if (job->state == JobState::kQueued) {
      RETURN_IF_ERROR(Apply(&*job, JobEvent::kCancel));
      job->error = "cancelled by request";
      RETURN_IF_ERROR(Save(*job));
      RETURN_IF_ERROR(CancelDependents(id, absl::StrCat("dependency ", id, " was cancelled")));
      return *job;
    }
    // Held: the worker sees the request in its next heartbeat and acknowledges it.
    job->cancel_requested = true;
    job->updated_ms = clock_->NowMs();
    RETURN_IF_ERROR(Save(*job));
    return *job;
  });
}

absl::StatusOr<Job> SqliteJobQueue::Get(const std::string& id) {
  std::lock_guard<std::mutex> lock(mutex_);
  ASSIGN_OR_RETURN(std::optional<Job> job, Load(id));
  if (!job) return absl::NotFoundError(absl::StrCat("job ", id, " not found"));
  return *job;
}

absl::StatusOr<std::vector<Job>> SqliteJobQueue::List(const JobFilter& filter) {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<Job> jobs;
  if (!filter.ids.empty()) {
    for (const std::string& id : filter.ids) {
      ASSIGN_OR_RETURN(std::optional<Job> job, Load(id));
      if (!job) return absl::NotFoundError(absl::StrCat("job ", id, " not found"));
      jobs.push_back(*job);
    }
    return jobs;
  }
  Statement s(db_, absl::StrCat("SELECT ", kColumns,
                                " FROM jobs WHERE (? = '' OR scene = ?) AND (? = 0 OR state = ?) "
                                "ORDER BY seq DESC LIMIT ?"));
  const int64_t state = filter.state ? Code(*filter.state) : 0;
  s.Bind(1, filter.scene).Bind(2, filter.scene).Bind(3, state).Bind(4, state);
  s.Bind(5, int64_t{filter.limit > 0 ? filter.limit : 100});
  while (true) {
    ASSIGN_OR_RETURN(bool row, s.Step());
    if (!row) break;
    jobs.push_back(RowToJob(s));
  }
  return jobs;
}

absl::StatusOr<QueueStats> SqliteJobQueue::Stats() {
  std::lock_guard<std::mutex> lock(mutex_);
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
  if (row && oldest.Int(0) > 0) stats.oldest_queued_age_ms = clock_->NowMs() - oldest.Int(0);
  return stats;
}

absl::StatusOr<int> SqliteJobQueue::RescueExpired() {
  return InTransaction([&]() -> absl::StatusOr<int> {
    Statement s(db_, "SELECT id FROM jobs WHERE state IN (?, ?) AND lease_expires_ms < ?");
    s.Bind(1, Code(JobState::kLeased)).Bind(2, Code(JobState::kRunning)).Bind(3, clock_->NowMs());
    std::vector<std::string> expired;
    while (true) {
      ASSIGN_OR_RETURN(bool row, s.Step());
      if (!row) break;
      expired.push_back(s.Text(0));
    }
    for (const std::string& id : expired) {
      ASSIGN_OR_RETURN(std::optional<Job> job, Load(id));
      RETURN_IF_ERROR(
          RetryOrFail(&*job,
                      absl::StrCat("lease of worker '", job->worker_id, "' expired (attempt ",
                                   job->attempts, " of ", job->max_attempts, ")"),
                      /*retryable=*/true));
    }
    return static_cast<int>(expired.size());
  });
}

}  // namespace instascene::scheduler
