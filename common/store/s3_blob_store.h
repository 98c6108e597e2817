// common/store/s3_blob_store.h: the content-addressed store on an S3-compatible object store
// (AWS S3, MinIO, Ceph RGW), for scale-out: every process that opens the same bucket and prefix
// sees the same blobs, so workers and schedulers need no store service between them.
//
// Layout under PREFIX: `cas/<hash>` (visible blobs), `uploads/<hash>-<size>` (resumable uploads:
// an S3 multipart upload, or the assembled object awaiting verification).
// - Put: the bytes are hashed here first; the PUT carries their SHA-256 (x-amz-content-sha256) and
//   MD5 (Content-MD5), which S3 servers check against the body, so a corrupted transfer is refused
//   by the server; a PUT is atomic (the object appears whole or not at all). A single verified PUT
//   rather than temporary key + read-back: half the requests and bytes for the many small blobs.
// - Append/FinishUpload (large blobs): appended bytes are buffered per upload up to `part_bytes`
//   and sent as multipart parts (S3's minimum part size is 5 MiB); `CommittedSize` counts the parts
//   S3 holds plus this process's buffer, so a client that restarts resumes at the last part S3
//   holds (ListMultipartUploads + ListParts; no local state needed). FinishUpload completes the
//   upload under `uploads/`, reads it back and hashes it, and only then copies it to `cas/`
//   (multipart copy above `copy_part_bytes`); a mismatch deletes it and nothing becomes visible.
// - FindMissing is one HEAD per digest (never a bucket listing), 16 in flight; Stats lists `cas/`.
// - Garbage collection (services/store/garbage_collection.h) reads an object's LastModified; every
//   presence check (FindMissing, Put, Grant, FinishUpload, ...) that finds a blob last written
//   longer than `touch_after_seconds` ago copies it onto itself (metadata replaced: S3's way to
//   set the time; a multipart self-copy above `copy_part_bytes`), so a blob a client is about to
//   reference again is young to the collector. Removal deletes the blob, then its grant under
//   each tenant folder of `grants/`.
// Abandoned multipart uploads are not visible and cost storage only: configure the bucket's
// lifecycle rule AbortIncompleteMultipartUpload (docs/DEPLOY.md).
#pragma once

#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "common/store/blob_store.h"
#include "common/store/s3_client.h"

namespace instascene::store {

struct S3StoreOptions {
  int64_t part_bytes = int64_t{8} << 20;          // multipart part size (S3 minimum: 5 MiB)
  int64_t copy_part_bytes = int64_t{1} << 30;     // above this, copy to cas/ by multipart copy
  int64_t verify_chunk_bytes = int64_t{8} << 20;  // read-back chunk when verifying an upload
  int max_buffered_uploads = 16;  // uploads holding an unsent buffer; the oldest is dropped
  // A blob found present and written longer ago than this is touched (see above): the collector's
  // grace period must exceed it plus the longest time from a client's FindMissing to its Submit.
  int64_t touch_after_seconds = 3600;

  absl::Status Validate() const;
};

class S3BlobStore final : public BlobStore {
 public:
  // Checks that the bucket is reachable with these credentials.
  static absl::StatusOr<std::unique_ptr<S3BlobStore>> Open(
      const S3Location& location, const S3Credentials& credentials, const StoreOptions& options,
      const S3StoreOptions& s3_options = {}, const S3ClientOptions& client_options = {});

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
  absl::StatusOr<std::vector<StoredBlob>> ListBlobs() override;
  absl::StatusOr<std::optional<std::chrono::system_clock::time_point>> BlobModified(
      const Digest& digest) override;
  absl::Status Remove(const Digest& digest) override;
  absl::StatusOr<std::vector<StoredGrant>> ListGrants() override;
  absl::Status RemoveGrant(const std::string& tenant, const Digest& digest) override;

  std::string BlobKey(const Digest& digest) const;
  // The upload's staging key: the shared one (space "") or a tenant's own.
  std::string UploadKey(const Digest& digest, const std::string& space = "") const;
  std::string GrantKey(const std::string& tenant, const Digest& digest) const;
  S3Client& client() { return *client_; }

 private:
  // One resumable upload: the multipart upload S3 holds and the bytes not yet sent as a part.
  struct Upload {
    std::mutex mutex;
    std::string key;         // UploadKey
    bool loaded = false;     // state read from S3
    bool assembled = false;  // the object under uploads/ is complete (awaits verification)
    std::string upload_id;   // "" = no multipart upload yet
    std::vector<S3Client::Part> parts;  // full parts S3 holds, numbered 1..n
    std::string buffer;                 // bytes after the parts
    int64_t durable() const;
  };

  S3BlobStore(std::unique_ptr<S3Client> client, StoreOptions options, S3StoreOptions s3_options)
      : client_(std::move(client)), options_(options), s3_options_(s3_options) {}
  // Whether the store holds the blob; touches it when found old (s3_collection.cc).
  absl::StatusOr<bool> Contains(const Digest& digest);
  absl::Status Touch(const Digest& digest);
  std::shared_ptr<Upload> GetUpload(const std::string& key);
  void Forget(const std::string& key);
  void NoteBuffered(const std::string& key);  // LRU of uploads holding a buffer
  absl::StatusOr<int64_t> PartSize(const Digest& digest, const std::string& space);
  absl::StatusOr<int64_t> AppendPart(const Digest& digest, const std::string& space, int64_t offset,
                                     absl::string_view data);
  absl::Status FinishPart(const Digest& digest, const std::string& space);
  absl::Status Load(const Digest& digest, Upload& upload);
  absl::Status SendFullParts(Upload& upload);
  absl::Status Assemble(const Digest& digest, Upload& upload);
  // Hashes the assembled upload; publishes it to cas/ or deletes it.
  absl::Status VerifyAndPublish(const Digest& digest, const std::string& key);
  absl::Status CopyToBlob(const std::string& from, const Digest& digest);

  std::unique_ptr<S3Client> client_;
  const StoreOptions options_;
  const S3StoreOptions s3_options_;
  std::mutex uploads_mutex_;
  std::map<std::string, std::shared_ptr<Upload>> uploads_;  // by UploadKey
  std::list<std::string> buffered_;                         // most recent last
};

}  // namespace instascene::store
