// services/scheduler/sqlite_schema.h: the SQLite job database's schema, version
// kSqliteSchemaVersion (stored as PRAGMA user_version), and the SQL that creates it or brings a
// version-1 database to it.
#pragma once

#include <string>

namespace instascene::scheduler {

inline constexpr int kSqliteSchemaVersion = 2;

// One transaction (BEGIN IMMEDIATE ... COMMIT) that creates the current schema and sets its
// version. from_v1: the database holds version 1's `jobs` table (one depends_on per job); every
// job is kept, the chain moved into named dependencies (job_dependencies), the old table dropped.
std::string SqliteMigrationSql(bool from_v1);

}  // namespace instascene::scheduler
