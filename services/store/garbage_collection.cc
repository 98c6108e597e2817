#include "services/store/garbage_collection.h"

#include <algorithm>
#include <chrono>
#include <set>
#include <string>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/store/manifest.h"

namespace instascene::store_service {
namespace {

// Adds a manifest and every file it lists to `live`. A manifest the store does not hold reaches
// nothing (counted); any other failure stops the collection.
absl::Status MarkManifest(store::BlobStore& store, const store::Digest& digest,
                          std::set<std::string>* live, GcReport* report) {
  if (!live->insert(digest.hash).second) return absl::OkStatus();  // marked already
  absl::StatusOr<store::Manifest> manifest = store::ReadManifest(store, digest);
  if (absl::IsNotFound(manifest.status())) {
    ++report->missing_manifests;
    return absl::OkStatus();
  }
  if (!manifest.ok()) {
    return absl::Status(manifest.status().code(),
                        absl::StrCat("manifest ", digest.ToString(), " (a job's root): ",
                                     manifest.status().message(), "; nothing removed"));
  }
  for (const auto& [path, file] : manifest->files) live->insert(file.hash);
  return absl::OkStatus();
}

// Every blob reachable from a job of the queue, newest job first, page by page.
absl::Status MarkFromJobs(store::BlobStore& store, scheduler::JobQueue& queue,
                          const GcOptions& options, std::set<std::string>* live, GcReport* report) {
  scheduler::JobFilter filter;
  filter.limit = options.page;
  for (;;) {
    ASSIGN_OR_RETURN(std::vector<scheduler::Job> jobs, queue.List(filter));
    for (const scheduler::Job& job : jobs) {
      ++report->jobs;
      RETURN_IF_ERROR(MarkManifest(store, job.scene_manifest, live, report));
      if (!job.output_manifest.hash.empty()) {
        RETURN_IF_ERROR(MarkManifest(store, job.output_manifest, live, report));
      }
    }
    if (static_cast<int>(jobs.size()) < filter.limit) return absl::OkStatus();
    filter.before_seq = jobs.back().seq;
  }
}

const std::string& HashOf(const store::StoredBlob& b) { return b.digest.hash; }
const std::string& HashOf(const std::string& hash) { return hash; }

// The grants whose blob the store does not hold (`listed`: the blobs listed, sorted by hash): every
// grant of a blob this collection removed (would remove, in a dry run), and a grant of a blob
// absent at the listing once the grant is older than `young_after` (a younger one may be of a blob
// written since). Each blob's absence is read again just before its grant's removal (re-uploaded
// since: the grant stays).
absl::Status SweepGrants(store::BlobStore& store, const std::vector<store::StoredBlob>& listed,
                         const std::set<std::string>& removed,
                         std::chrono::system_clock::time_point young_after, bool dry_run,
                         GcReport* report) {
  ASSIGN_OR_RETURN(const std::vector<store::StoredGrant> grants, store.ListGrants());
  for (const store::StoredGrant& g : grants) {
    ++report->grants;
    const bool of_removed = removed.count(g.digest.hash) > 0;
    const bool was_listed =
        std::binary_search(listed.begin(), listed.end(), g.digest.hash,
                           [](const auto& a, const auto& b) { return HashOf(a) < HashOf(b); });
    if (!of_removed && (was_listed || g.modified > young_after)) continue;
    if (!dry_run) {
      ASSIGN_OR_RETURN(const auto modified, store.BlobModified(g.digest));
      if (modified.has_value()) continue;
      RETURN_IF_ERROR(store.RemoveGrant(g.tenant, g.digest));
    }
    ++report->removed_grants;
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<GcReport> CollectGarbage(store::BlobStore& store, scheduler::JobQueue& queue,
                                        const GcOptions& options) {
  if (options.grace.count() < 0 || options.page < 1) {
    return absl::InvalidArgumentError("gc: the grace period must be >= 0 and the page >= 1");
  }
  const auto young_after = options.now.value_or(std::chrono::system_clock::now()) - options.grace;
  GcReport report;
  // Listed before the roots are read (the header says why).
  ASSIGN_OR_RETURN(const std::vector<store::StoredBlob> blobs, store.ListBlobs());
  std::set<std::string> live, removed;
  RETURN_IF_ERROR(MarkFromJobs(store, queue, options, &live, &report));
  for (const store::StoredBlob& b : blobs) {
    ++report.blobs;
    report.bytes += b.digest.size_bytes;
    if (live.count(b.digest.hash)) {
      ++report.live_blobs;
    } else if (b.modified > young_after) {
      ++report.young_blobs;
    } else {
      if (!options.dry_run) {
        ASSIGN_OR_RETURN(const auto modified, store.BlobModified(b.digest));
        if (!modified.has_value() || *modified > young_after) {
          ++report.raced_blobs;
          continue;
        }
        RETURN_IF_ERROR(store.Remove(b.digest));
      }
      removed.insert(b.digest.hash);
      ++report.removed_blobs;
      report.removed_bytes += b.digest.size_bytes;
    }
  }
  RETURN_IF_ERROR(SweepGrants(store, blobs, removed, young_after, options.dry_run, &report));
  return report;
}

}  // namespace instascene::store_service
