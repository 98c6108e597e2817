#include "services/scheduler/sqlite_schema.h"

#include "absl/strings/str_cat.h"

namespace instascene::scheduler {

std::string SqliteMigrationSql(bool from_v1) {
  std::string sql = "BEGIN IMMEDIATE;";
  if (from_v1) {
    // Version 1 (one depends_on per job): keep every job, move the chain into named dependencies.
    absl::StrAppend(&sql, R"sql(
      ALTER TABLE jobs RENAME TO jobs_v1;
      DROP INDEX IF EXISTS jobs_by_state; DROP INDEX IF EXISTS jobs_by_scene;
      DROP INDEX IF EXISTS jobs_by_dependency;)sql");
  }
  absl::StrAppend(&sql, R"sql(
    CREATE TABLE jobs (
      seq INTEGER PRIMARY KEY AUTOINCREMENT,
      id TEXT NOT NULL UNIQUE, key TEXT NOT NULL UNIQUE, scene TEXT NOT NULL, kind TEXT NOT NULL,
      parameters TEXT NOT NULL, scene_manifest TEXT NOT NULL, parent TEXT NOT NULL,
      item INTEGER NOT NULL, pending INTEGER NOT NULL, items INTEGER NOT NULL, plans TEXT NOT NULL,
      state INTEGER NOT NULL, priority INTEGER NOT NULL, attempts INTEGER NOT NULL,
      max_attempts INTEGER NOT NULL, output TEXT NOT NULL, error TEXT NOT NULL,
      worker TEXT NOT NULL, lease_token TEXT NOT NULL, progress TEXT NOT NULL,
      cancel_requested INTEGER NOT NULL, created_ms INTEGER NOT NULL, updated_ms INTEGER NOT NULL,
      not_before_ms INTEGER NOT NULL, lease_expires_ms INTEGER NOT NULL, lease_ms INTEGER NOT NULL);
    CREATE INDEX jobs_ready ON jobs(state, pending, kind);
    CREATE INDEX jobs_by_scene ON jobs(scene);
    CREATE TABLE job_dependencies (job_id TEXT NOT NULL, name TEXT NOT NULL,
      dependency_id TEXT NOT NULL, PRIMARY KEY (job_id, name));
    CREATE INDEX dependencies_by_dependency ON job_dependencies(dependency_id);
    CREATE TABLE IF NOT EXISTS scenes (scene TEXT PRIMARY KEY, last_lease_ms INTEGER NOT NULL);)sql");
  if (from_v1) {
    absl::StrAppend(&sql, R"sql(
      INSERT INTO jobs (seq, id, key, scene, kind, parameters, scene_manifest, parent, item,
        pending, items, plans, state, priority, attempts, max_attempts, output, error, worker,
        lease_token, progress, cancel_requested, created_ms, updated_ms, not_before_ms,
        lease_expires_ms, lease_ms)
      SELECT seq, id, key, scene, kind, parameters, scene_manifest, '', -1, 0, -1, '[]', state,
        priority, attempts, max_attempts, output, error, worker, lease_token, progress,
        cancel_requested, created_ms, updated_ms, not_before_ms, lease_expires_ms, 0 FROM jobs_v1;
      INSERT INTO job_dependencies (job_id, name, dependency_id)
        SELECT j.id, d.kind, j.depends_on FROM jobs_v1 j JOIN jobs_v1 d ON d.id = j.depends_on;
      UPDATE jobs SET pending = (SELECT COUNT(*) FROM job_dependencies e JOIN jobs d
        ON d.id = e.dependency_id WHERE e.job_id = jobs.id AND d.state != 4);
      DROP TABLE jobs_v1;)sql");
  }
  absl::StrAppend(&sql, "PRAGMA user_version = ", kSqliteSchemaVersion, "; COMMIT;");
  return sql;
}

}  // namespace instascene::scheduler
