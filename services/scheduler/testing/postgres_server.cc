#include "services/scheduler/testing/postgres_server.h"

#include <unistd.h>

#include <cstdlib>
#include <filesystem>

#include "absl/strings/str_cat.h"

namespace instascene::scheduler::testing {
namespace {

int Run(const std::string& command) { return std::system(command.c_str()); }

std::string FindPostgresBin() {
  namespace fs = std::filesystem;
  for (const char* version : {"15", "16", "17", "14"}) {
    const fs::path bin = fs::path("/usr/lib/postgresql") / version / "bin";
    if (fs::exists(bin / "initdb") && fs::exists(bin / "pg_ctl")) return bin.string();
  }
  return "";
}

}  // namespace

absl::StatusOr<std::unique_ptr<PostgresServer>> PostgresServer::Start() {
  std::unique_ptr<PostgresServer> s(new PostgresServer());
  s->bin_ = FindPostgresBin();
  if (s->bin_.empty())
    return absl::FailedPreconditionError(
        "no PostgreSQL server binaries under /usr/lib/postgresql (scripts/install-deps.sh "
        "installs postgresql-15)");
  s->dir_ = std::make_unique<instascene::testing::ScopedTempDir>("postgres");
  const std::string root = s->dir_->str();
  s->data_ = root + "/data";
  if (::geteuid() == 0) {
    s->as_user_ = "runuser -u postgres -- ";
    if (Run(absl::StrCat("chown postgres: '", root, "'")) != 0)
      return absl::InternalError("cannot hand the scratch directory to the postgres user");
  }
  if (Run(absl::StrCat(s->as_user_, s->bin_, "/initdb -D '", s->data_,
                       "' -U postgres --auth=trust -E UTF8 --no-sync > '", root,
                       "/initdb.log' 2>&1")) != 0)
    return absl::InternalError(absl::StrCat("initdb failed (", root, "/initdb.log)"));
  const std::string options = absl::StrCat("-c listen_addresses='' -c unix_socket_directories='",
                                           root, "' -c fsync=off -c max_connections=50 -p 5433");
  if (Run(absl::StrCat(s->as_user_, s->bin_, "/pg_ctl -D '", s->data_, "' -o \"", options,
                       "\" -l '", root, "/server.log' -w -t 60 start > /dev/null 2>&1")) != 0)
    return absl::InternalError(absl::StrCat("pg_ctl start failed (", root, "/server.log)"));
  s->started_ = true;
  s->conninfo_ = absl::StrCat("host=", root, " port=5433 user=postgres dbname=postgres");
  return s;
}

PostgresServer::~PostgresServer() {
  if (started_)
    Run(absl::StrCat(as_user_, bin_, "/pg_ctl -D '", data_,
                     "' -m immediate -w stop > /dev/null 2>&1"));
}

}  // namespace instascene::scheduler::testing
