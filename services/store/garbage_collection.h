// services/store/garbage_collection.h: garbage collection of the embedded default's filesystem
// store. The roots are the job queue's jobs, in any state: each job's scene manifest and, once it
// succeeded, its output manifest, with every file they list. A blob no root reaches is removed
// (with its tenants' grants) once its file is older than the grace period: a client uploads a
// scene's files before it submits the scene, and FindMissing / Put make a blob young again when
// they find it present, so a blob about to be referenced is never collected.
//
// Offline: the caller opens the store and the queue, which takes both folders' file locks, so no
// node can serve them meanwhile (`instascene gc` refuses a data directory in use).
#pragma once

#include <chrono>
#include <cstdint>

#include "absl/status/statusor.h"
#include "common/store/blob_store.h"
#include "services/scheduler/job_queue.h"

namespace instascene::store_service {

struct GcOptions {
  std::chrono::seconds grace{24 * 3600};  // unreachable blobs younger than this stay
  bool dry_run = false;                   // count what would be removed, remove nothing
  int page = 1000;                        // jobs read per query
};

struct GcReport {
  int64_t jobs = 0;                              // roots read
  int64_t blobs = 0, bytes = 0;                  // in the store before collecting
  int64_t live_blobs = 0;                        // reached from a job
  int64_t young_blobs = 0;                       // unreachable but inside the grace period
  int64_t removed_blobs = 0, removed_bytes = 0;  // (would be, with dry_run)
  int64_t missing_manifests = 0;                 // referenced by a job but not in the store
};

// Marks from every job, then sweeps. Stops before removing anything if a manifest a job names
// cannot be read for another reason than its absence (a damaged manifest could hide live blobs).
absl::StatusOr<GcReport> CollectGarbage(store::FilesystemBlobStore& store,
                                        scheduler::JobQueue& queue, const GcOptions& options);

}  // namespace instascene::store_service
