// `instascene gc`: garbage collection of the store (services/store/garbage_collection.h). The
// embedded default's (--data: DATA/store, roots from DATA/jobs.db) offline: it takes both file
// locks, so it refuses a data directory a running `instascene serve` holds. Scale-out storage
// (--store s3://... --queue postgres://...) with the services running.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>

#include <nlohmann/json.hpp>

#include "clients/cli/cli.h"
#include "common/core/status.h"
#include "common/store/blob_store_uri.h"
#include "services/scheduler/queue_uri.h"
#include "services/scheduler/sqlite_queue_store.h"
#include "services/store/garbage_collection.h"

namespace instascene::cli {
namespace {

struct GcArgs {
  std::string data = "instascene-data";
  std::string store, queue;  // scale-out: both, instead of --data
  double grace_hours = 24;
  bool dry_run = false, json = false;
};

// The store and the queue to collect: --store and --queue (scale-out), else --data's.
absl::Status OpenTargets(const GcArgs& a, std::unique_ptr<store::BlobStore>* blobs,
                         std::unique_ptr<scheduler::JobQueue>* queue) {
  if (!a.store.empty() || !a.queue.empty()) {
    if (a.store.empty() || a.queue.empty())
      return absl::InvalidArgumentError("--store and --queue go together (scale-out storage)");
    if (!store::IsBlobStoreUri(a.store))
      return absl::InvalidArgumentError(
          "--store: the storage itself (s3://... or file:DIR), not a store service's address");
    ASSIGN_OR_RETURN(*blobs, store::OpenBlobStoreUri(a.store, {}));
    ASSIGN_OR_RETURN(*queue, scheduler::OpenJobQueueUri(a.queue, {}));
    return absl::OkStatus();
  }
  const std::filesystem::path data(a.data);
  if (!std::filesystem::exists(data / "jobs.db") || !std::filesystem::is_directory(data / "store"))
    return absl::NotFoundError(absl::StrCat(
        a.data, ": not the data directory of `instascene serve` (no jobs.db and store/)"));
  ASSIGN_OR_RETURN(*blobs, store::FilesystemBlobStore::Open((data / "store").string(), {}));
  ASSIGN_OR_RETURN(*queue, scheduler::OpenSqliteJobQueue((data / "jobs.db").string(), {}));
  return absl::OkStatus();
}

// The summary on stderr, and the report as JSON on stdout with --json.
void PrintReport(const store_service::GcReport& r, const GcArgs& a) {
  auto n = [](int64_t v) { return static_cast<long long>(v); };
  std::fprintf(stderr,
               "gc: %lld jobs; %lld blobs (%lld bytes): %lld reached from a job, %lld younger than "
               "the grace period; %s %lld blobs (%lld bytes) and %lld of %lld grants%s%s\n",
               n(r.jobs), n(r.blobs), n(r.bytes), n(r.live_blobs), n(r.young_blobs),
               a.dry_run ? "would remove" : "removed", n(r.removed_blobs), n(r.removed_bytes),
               n(r.removed_grants), n(r.grants),
               r.missing_manifests > 0 ? "; some jobs name manifests the store lacks" : "",
               r.raced_blobs > 0 ? "; some were found present again meanwhile and kept" : "");
  if (!a.json) return;
  PrintJsonLine(nlohmann::json({{"jobs", r.jobs},
                                {"blobs", r.blobs},
                                {"bytes", r.bytes},
                                {"live_blobs", r.live_blobs},
                                {"young_blobs", r.young_blobs},
                                {"removed_blobs", r.removed_blobs},
                                {"removed_bytes", r.removed_bytes},
                                {"missing_manifests", r.missing_manifests},
                                {"raced_blobs", r.raced_blobs},
                                {"grants", r.grants},
                                {"removed_grants", r.removed_grants},
                                {"dry_run", a.dry_run}})
                    .dump());
}

absl::Status RunGc(const GcArgs& a) {
  if (!(a.grace_hours >= 0) || a.grace_hours > 24 * 365 * 100)
    return absl::InvalidArgumentError("--grace-hours: in [0, 876000]");
  std::unique_ptr<store::BlobStore> blobs;
  std::unique_ptr<scheduler::JobQueue> queue;
  RETURN_IF_ERROR(OpenTargets(a, &blobs, &queue));
  store_service::GcOptions options;
  options.grace = std::chrono::seconds(static_cast<int64_t>(a.grace_hours * 3600));
  options.dry_run = a.dry_run;
  ASSIGN_OR_RETURN(const store_service::GcReport r,
                   store_service::CollectGarbage(*blobs, *queue, options));
  PrintReport(r, a);
  return absl::OkStatus();
}

}  // namespace

void AddGcCommand(CLI::App& app, Action* action) {
  auto args = std::make_shared<GcArgs>();
  CLI::App* cmd = app.add_subcommand(
      "gc",
      "Remove the store's blobs no job reaches, once older than a grace period: the embedded "
      "default's (--data: DATA/store, jobs from DATA/jobs.db; with the server stopped) or "
      "scale-out storage (--store and --queue; with the services running)");
  cmd->add_option("--data", args->data, "Data directory of `instascene serve`")
      ->capture_default_str();
  cmd->add_option("--store", args->store,
                  "Scale-out: the storage (s3://BUCKET/PREFIX?endpoint=URL&region=R, credentials "
                  "from AWS_ACCESS_KEY_ID/AWS_SECRET_ACCESS_KEY or ~/.aws/credentials)");
  cmd->add_option("--queue", args->queue,
                  "Scale-out: the job queue the schedulers share (postgres://HOST[:PORT]/DB, "
                  "password from PGPASSWORD or ~/.pgpass)");
  cmd->add_option("--grace-hours", args->grace_hours,
                  "Unreachable blobs younger than this stay (uploads not yet submitted; with "
                  "services running it must exceed the store's touch interval, 1 h on S3, plus "
                  "the longest upload-to-submit time)")
      ->capture_default_str();
  cmd->add_flag("--dry-run", args->dry_run, "Count what would be removed, remove nothing");
  cmd->add_flag("--json", args->json, "Print a JSON summary as the last stdout line");
  cmd->callback([args, action] { *action = [args] { return RunGc(*args); }; });
}

}  // namespace instascene::cli
