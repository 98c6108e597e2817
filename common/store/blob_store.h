// common/store/blob_store.h: the content-addressed blob store. `BlobStore` is the interface every
// stage and client codes against (filesystem here; the gRPC client in services/store and, later, S3
// implement it too); `FilesystemBlobStore` is the embedded default.
//
// Guarantees (every implementation): a blob becomes visible only after its bytes were verified
// against the claimed digest; a rejected write leaves nothing behind; interrupted uploads can be
// resumed at their committed size. Thread-safe.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "common/core/file_lock.h"
#include "common/store/digest.h"

namespace instascene::store {

struct StoreOptions {
  int64_t max_blob_bytes = int64_t{16} << 30;  // larger blobs are refused (bytes)
  int64_t max_batch_bytes = int64_t{4} << 20;  // limit of one batch RPC / Put of a small blob
  bool verify_reads = false;                   // re-hash blobs on every full read
  // Interrupted uploads untouched for this long are removed (filesystem store: at open and at
  // most once a minute when an upload starts; S3: the bucket's AbortIncompleteMultipartUpload
  // lifecycle rule, docs/DEPLOY.md). 0 = keep them for ever.
  int64_t upload_ttl_seconds = 24 * 3600;
  // The most bytes of blobs granted to one tenant (its uploads and its jobs' outputs) before the
  // store service refuses the tenant's new uploads (0 = no limit). Enforced by the store service
  // (services/store/tenant_quota.h), read here so that every binary's --store flags set it.
  int64_t tenant_quota_bytes = int64_t{256} << 30;

  absl::Status Validate() const;
};

struct StoreStats {
  int64_t blob_count = 0;
  int64_t total_bytes = 0;
  int64_t partial_uploads = 0;  // interrupted uploads still resumable
  int64_t partial_bytes = 0;
  int64_t expired_uploads = 0;  // removed by the TTL since the store was opened
};

// A committed blob as the garbage collector sees it (services/store/garbage_collection.h): its
// digest and when it was last written, or last found present by FindMissing / Put (each backend
// documents how it keeps a blob about to be referenced young).
struct StoredBlob {
  Digest digest;
  std::chrono::system_clock::time_point modified;
};

// A tenant's grant of a blob as the garbage collector sees it: the blob it names (which the
// store may no longer hold) and when the grant was written.
struct StoredGrant {
  std::string tenant;
  Digest digest;
  std::chrono::system_clock::time_point modified;
};

// The order ListGrants returns: by tenant, then hash.
bool GrantOrder(const StoredGrant& a, const StoredGrant& b);

// Progress of a transfer: bytes done, bytes total.
using TransferProgress = std::function<void(int64_t done, int64_t total)>;

// Checks every backend makes before a write: a well-formed digest within the size limit
// (InvalidArgument / ResourceExhausted), and bytes that match it (InvalidArgument, "nothing
// stored").
absl::Status CheckWritable(const Digest& digest, const StoreOptions& options);
absl::Status VerifyBlobBytes(const Digest& digest, absl::string_view bytes);
// An append of `bytes` at `offset` to an upload with `committed` bytes: it must start there
// (FailedPrecondition: resume at the committed size) and stay within the digest's size
// (InvalidArgument).
absl::Status CheckAppend(const Digest& digest, int64_t offset, int64_t committed, size_t bytes);
// The size a grant's name (HASH-SIZE, both backends) records; DataLoss for another name.
absl::StatusOr<int64_t> GrantNameBytes(absl::string_view name);
// The digest a grant's name records; nullopt for a name that is not HASH-SIZE of a valid digest.
std::optional<Digest> GrantNameDigest(absl::string_view name);
// A tenant name safe as a path or key component: 1-32 of [a-z0-9-], not starting with '-' (the
// rule common/auth/tokens.h documents; checked here too because the store sits below auth).
absl::Status CheckTenantName(absl::string_view tenant);

class BlobStore {
 public:
  virtual ~BlobStore() = default;

  virtual const StoreOptions& options() const = 0;
  // The digests (of `digests`) the store does not hold.
  virtual absl::StatusOr<std::vector<Digest>> FindMissing(const std::vector<Digest>& digests) = 0;
  // Stores a blob after verifying its bytes (InvalidArgument on mismatch, nothing stored).
  virtual absl::Status Put(const Digest& digest, absl::string_view bytes) = 0;
  // A blob's bytes, or a range of them (limit 0 = to the end). NotFound if absent.
  virtual absl::StatusOr<std::string> Read(const Digest& digest, int64_t offset = 0,
                                           int64_t limit = 0) = 0;

  // Resumable uploads of large blobs: bytes committed so far (the full size once the blob is in
  // the store), append at exactly that offset, then finish (verify + publish).
  virtual absl::StatusOr<int64_t> CommittedSize(const Digest& digest) = 0;
  virtual absl::StatusOr<int64_t> Append(const Digest& digest, int64_t offset,
                                         absl::string_view data) = 0;
  virtual absl::Status FinishUpload(const Digest& digest) = 0;

  virtual absl::StatusOr<StoreStats> Stats() = 0;

  // Uploads a local file as `digest` (resuming an interrupted upload); no-op if present.
  virtual absl::Status PutFile(const Digest& digest, const std::string& path,
                               const TransferProgress& progress = nullptr);
  // Downloads a blob into a local file (written to a temp file, verified, renamed).
  virtual absl::Status GetFile(const Digest& digest, const std::string& path);

  // Tenants (docs/SERVICES.md, "Authentication and tenants"). The store is shared, but a tenant
  // sees only the blobs granted to it: those it uploaded itself (proving it holds the bytes) and
  // those jobs of its scenes wrote. A grant is a marker beside the blob; granting a blob the store
  // lacks is FailedPrecondition. The base class has none (Unimplemented).
  virtual absl::Status Grant(const std::string& tenant, const std::vector<Digest>& digests);
  // The digests (of `digests`) not granted to `tenant`, whether or not the store holds them.
  virtual absl::StatusOr<std::vector<Digest>> FindUngranted(const std::string& tenant,
                                                            const std::vector<Digest>& digests);
  // A tenant's own resumable upload, staged apart from everyone else's: its progress says nothing
  // about whether the store or another tenant holds the blob. Finishing verifies the bytes,
  // publishes them when the store lacks the blob (else drops them) and grants the blob.
  virtual absl::StatusOr<int64_t> TenantCommittedSize(const std::string& tenant,
                                                      const Digest& digest);
  virtual absl::StatusOr<int64_t> TenantAppend(const std::string& tenant, const Digest& digest,
                                               int64_t offset, absl::string_view data);
  virtual absl::Status TenantFinishUpload(const std::string& tenant, const Digest& digest);
  // The bytes of every blob granted to `tenant`, read from the grants' names (the garbage
  // collector removes the grants of a blob it removed). The base class has none (Unimplemented).
  virtual absl::StatusOr<int64_t> TenantBytes(const std::string& tenant);

  // Garbage collection (services/store/garbage_collection.h); the base class has none
  // (Unimplemented). Every committed blob, sorted by hash; one blob's modification time (nullopt:
  // absent), read again just before its removal; the removal of a blob (its grants stay: the
  // collector removes them). Every tenant's every grant, sorted by tenant and hash (a grant's
  // blob may be absent); the removal of one grant. Removing what is absent is not an error.
  virtual absl::StatusOr<std::vector<StoredBlob>> ListBlobs();
  virtual absl::StatusOr<std::optional<std::chrono::system_clock::time_point>> BlobModified(
      const Digest& digest);
  virtual absl::Status Remove(const Digest& digest);
  virtual absl::StatusOr<std::vector<StoredGrant>> ListGrants();
  virtual absl::Status RemoveGrant(const std::string& tenant, const Digest& digest);
};

// Blobs under <root>/cas/<hash[0:2]>/<hash>, interrupted uploads under <root>/uploads/ (a
// tenant's own as <tenant>.<hash>-<size>.part), grants as empty files
// <root>/grants/<tenant>/<hash[0:2]>/<hash>-<size>, temp files under <root>/tmp/ (cleared at open).
// Writes: temp file + fsync + rename + directory fsync.
class FilesystemBlobStore final : public BlobStore {
 public:
  static absl::StatusOr<std::unique_ptr<FilesystemBlobStore>> Open(const std::string& root,
                                                                   const StoreOptions& options);

  const StoreOptions& options() const override { return options_; }
  absl::StatusOr<std::vector<Digest>> FindMissing(const std::vector<Digest>& digests) override;
  absl::Status Put(const Digest& digest, absl::string_view bytes) override;
  absl::StatusOr<std::string> Read(const Digest& digest, int64_t offset = 0,
                                   int64_t limit = 0) override;
  absl::StatusOr<int64_t> CommittedSize(const Digest& digest) override;
  absl::StatusOr<int64_t> Append(const Digest& digest, int64_t offset,
                                 absl::string_view data) override;
  absl::Status FinishUpload(const Digest& digest) override;
  absl::StatusOr<StoreStats> Stats() override;
  absl::Status Grant(const std::string& tenant, const std::vector<Digest>& digests) override;
  absl::StatusOr<std::vector<Digest>> FindUngranted(const std::string& tenant,
                                                    const std::vector<Digest>& digests) override;
  absl::StatusOr<int64_t> TenantCommittedSize(const std::string& tenant,
                                              const Digest& digest) override;
  absl::StatusOr<int64_t> TenantAppend(const std::string& tenant, const Digest& digest,
                                       int64_t offset, absl::string_view data) override;
  absl::Status TenantFinishUpload(const std::string& tenant, const Digest& digest) override;
  absl::StatusOr<int64_t> TenantBytes(const std::string& tenant) override;

  std::string BlobPath(const Digest& digest) const;

  // Garbage collection: a blob's file modification time is set when the blob is written and
  // again whenever FindMissing or Put finds it present. Offline only (the folder's file lock).
  absl::StatusOr<std::vector<StoredBlob>> ListBlobs() override;
  absl::StatusOr<std::optional<std::chrono::system_clock::time_point>> BlobModified(
      const Digest& digest) override;
  absl::Status Remove(const Digest& digest) override;
  absl::StatusOr<std::vector<StoredGrant>> ListGrants() override;
  absl::Status RemoveGrant(const std::string& tenant, const Digest& digest) override;

 private:
  FilesystemBlobStore(std::string root, StoreOptions options, FileLock lock)
      : root_(std::move(root)), options_(options), lock_(std::move(lock)) {}
  // The upload's part file: the shared one (space "") or a tenant's own.
  std::string PartPath(const Digest& digest, const std::string& space = "") const;
  std::string GrantPath(const std::string& tenant, const Digest& digest) const;
  absl::StatusOr<int64_t> AppendPart(const Digest& digest, const std::string& space, int64_t offset,
                                     absl::string_view data);
  absl::Status FinishPart(const Digest& digest, const std::string& space);
  // Removes interrupted uploads older than the TTL; `force` = now, else at most once a minute.
  void ExpireUploads(bool force);
  bool Contains(const Digest& digest) const;
  void Touch(const Digest& digest) const;  // its file's modification time = now
  // Moves a verified file into cas/ (fsync + rename + directory fsync).
  absl::Status Publish(const std::string& from, const Digest& digest);

  const std::string root_;
  const StoreOptions options_;
  FileLock lock_;            // one process owns the folder (it clears tmp/ at open)
  std::mutex upload_mutex_;  // serialises Append / FinishUpload (one part file per digest)
  std::mutex temp_mutex_;
  uint64_t temp_counter_ = 0;
  std::atomic<int64_t> last_sweep_ms_{0};
  std::atomic<int64_t> expired_uploads_{0};
};

}  // namespace instascene::store
