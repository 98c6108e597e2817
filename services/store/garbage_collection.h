// services/store/garbage_collection.h: garbage collection of the content-addressed store, for the
// embedded default (filesystem store + SQLite queue, offline) and for scale-out (S3 + PostgreSQL,
// with the services running). The roots are the job queue's jobs, in any state: each job's scene
// manifest and, once it succeeded, its output manifest, with every file they list. A blob no root
// reaches is removed once it is older than the grace period; then every grant whose blob the store
// does not hold goes: those of the blobs just removed, and orphans (a grant written in the round
// trip between a blob's removal and the listing of the grants) once older than the grace period.
//
// Why concurrent clients stay safe: a client uploads a scene's files before it submits the scene
// (new blobs are young), and FindMissing / Put make a blob they find present young again (the
// filesystem store on every check, S3 when it was written over `touch_after_seconds` ago). The
// collector lists the blobs first and reads the roots after, so a job submitted after the roots
// were read references only blobs young at the listing, provided the grace period exceeds the
// touch interval plus the longest FindMissing-to-Submit time. Each blob's time is read again
// just before its removal; what remains is the one round trip between that read and the delete,
// and a job that loses a blob there fails with NotFound naming it (submitting again re-uploads
// it).
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>

#include "absl/status/statusor.h"
#include "common/store/blob_store.h"
#include "services/scheduler/job_queue.h"

namespace instascene::store_service {

struct GcOptions {
  std::chrono::seconds grace{24 * 3600};  // unreachable blobs younger than this stay
  bool dry_run = false;                   // count what would be removed, remove nothing
  int page = 1000;                        // jobs read per query
  // The collection's clock (tests move it; unset: the system clock when the collection starts).
  std::optional<std::chrono::system_clock::time_point> now;
};

struct GcReport {
  int64_t jobs = 0;                              // roots read
  int64_t blobs = 0, bytes = 0;                  // in the store before collecting
  int64_t live_blobs = 0;                        // reached from a job
  int64_t young_blobs = 0;                       // unreachable but inside the grace period
  int64_t removed_blobs = 0, removed_bytes = 0;  // (would be, with dry_run)
  int64_t missing_manifests = 0;                 // referenced by a job but not in the store
  int64_t raced_blobs = 0;     // old at the listing but gone or young again at removal: kept
  int64_t grants = 0;          // tenants' grants listed after the blobs were swept
  int64_t removed_grants = 0;  // of blobs the store does not hold (would be, with dry_run)
};

// Lists the blobs, marks from every job, then sweeps the blobs and the grants. Stops before
// removing anything if a
// manifest a job names cannot be read for another reason than its absence (a damaged manifest
// could hide live blobs). The store must implement ListBlobs / BlobModified / Remove (file: and
// s3:// storage; a store service's client does not).
absl::StatusOr<GcReport> CollectGarbage(store::BlobStore& store, scheduler::JobQueue& queue,
                                        const GcOptions& options);

}  // namespace instascene::store_service
