// services/scheduler/testing/postgres_server.h: a real PostgreSQL for tests, started by the test
// itself: initdb into a scoped temporary directory, the server on a Unix socket in that directory
// only (no TCP port to collide with), stopped and removed at the end. As root (CI), the server runs
// as the `postgres` user (initdb refuses root). Needs Debian's postgresql-15 (install-deps.sh).
#pragma once

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "common/core/testing/temp_dir.h"

namespace instascene::scheduler::testing {

class PostgresServer {
 public:
  static absl::StatusOr<std::unique_ptr<PostgresServer>> Start();
  ~PostgresServer();

  // libpq connection string for the `postgres` database.
  const std::string& conninfo() const { return conninfo_; }

 private:
  PostgresServer() = default;
  std::unique_ptr<instascene::testing::ScopedTempDir> dir_;
  std::string bin_, data_, conninfo_, as_user_;
  bool started_ = false;
};

}  // namespace instascene::scheduler::testing
