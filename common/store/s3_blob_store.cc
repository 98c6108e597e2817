#include "common/store/s3_blob_store.h"

#include <algorithm>
#include <atomic>
#include <thread>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene::store {
namespace {

constexpr int64_t kMiB = int64_t{1} << 20;
constexpr int64_t kMaxSinglePut = int64_t{5} << 30;  // S3's limit of one PUT (and of a part)
constexpr size_t kMaxTrackedUploads = 4096;
constexpr size_t kFindMissingConcurrency = 16;

}  // namespace

absl::Status S3StoreOptions::Validate() const {
  if (part_bytes < 5 * kMiB || part_bytes > kMaxSinglePut)
    return absl::InvalidArgumentError("S3 part size must be in [5 MiB, 5 GiB]");
  if (copy_part_bytes < 5 * kMiB || copy_part_bytes > kMaxSinglePut)
    return absl::InvalidArgumentError("S3 copy part size must be in [5 MiB, 5 GiB]");
  if (verify_chunk_bytes < 1) return absl::InvalidArgumentError("verify chunk must be positive");
  if (max_buffered_uploads < 1)
    return absl::InvalidArgumentError("max_buffered_uploads must be >= 1");
  return absl::OkStatus();
}

int64_t S3BlobStore::Upload::durable() const {
  int64_t total = 0;
  for (const S3Client::Part& p : parts) total += p.size;
  return total;
}

absl::StatusOr<std::unique_ptr<S3BlobStore>> S3BlobStore::Open(
    const S3Location& location, const S3Credentials& credentials, const StoreOptions& options,
    const S3StoreOptions& s3_options, const S3ClientOptions& client_options) {
  RETURN_IF_ERROR(options.Validate());
  RETURN_IF_ERROR(s3_options.Validate());
  auto client = std::make_unique<S3Client>(location, credentials, client_options);
  RETURN_IF_ERROR(client->HeadBucket());
  return std::unique_ptr<S3BlobStore>(new S3BlobStore(std::move(client), options, s3_options));
}

std::string S3BlobStore::BlobKey(const Digest& digest) const {
  return absl::StrCat(client_->location().prefix, "cas/", digest.hash);
}

std::string S3BlobStore::UploadKey(const Digest& digest, const std::string& space) const {
  return absl::StrCat(client_->location().prefix, "uploads/", space, space.empty() ? "" : "/",
                      digest.hash, "-", digest.size_bytes);
}

std::string S3BlobStore::GrantKey(const std::string& tenant, const Digest& digest) const {
  return absl::StrCat(client_->location().prefix, "grants/", tenant, "/", digest.hash, "-",
                      digest.size_bytes);
}

absl::StatusOr<bool> S3BlobStore::Contains(const Digest& digest) {
  ASSIGN_OR_RETURN(std::optional<int64_t> size, client_->HeadObject(BlobKey(digest)));
  return size.has_value() && *size == digest.size_bytes;
}

absl::StatusOr<std::vector<Digest>> S3BlobStore::FindMissing(const std::vector<Digest>& digests) {
  for (const Digest& d : digests) RETURN_IF_ERROR(ValidateDigest(d));
  // One HEAD per digest, kFindMissingConcurrency in flight (network-bound: a scene upload asks for
  // hundreds); the answer keeps the request's order.
  std::vector<char> present(digests.size(), 0);
  std::vector<absl::Status> errors(digests.size());
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t i; (i = next.fetch_add(1)) < digests.size();) {
      absl::StatusOr<bool> found = Contains(digests[i]);
      if (found.ok())
        present[i] = *found;
      else
        errors[i] = found.status();
    }
  };
  const size_t threads = std::min(kFindMissingConcurrency, digests.size());
  std::vector<std::thread> pool;
  for (size_t t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
  std::vector<Digest> missing;
  for (size_t i = 0; i < digests.size(); ++i) {
    RETURN_IF_ERROR(errors[i]);
    if (!present[i]) missing.push_back(digests[i]);
  }
  return missing;
}

absl::Status S3BlobStore::Put(const Digest& digest, absl::string_view bytes) {
  RETURN_IF_ERROR(CheckWritable(digest, options_));
  RETURN_IF_ERROR(VerifyBlobBytes(digest, bytes));
  ASSIGN_OR_RETURN(bool present, Contains(digest));
  if (present) return absl::OkStatus();
  if (digest.size_bytes <= kMaxSinglePut) return client_->PutObject(BlobKey(digest), bytes);
  int64_t offset = 0;  // beyond one PUT: the resumable path
  while (offset < digest.size_bytes) {
    const int64_t n = std::min(s3_options_.part_bytes, digest.size_bytes - offset);
    ASSIGN_OR_RETURN(offset, Append(digest, offset, bytes.substr(offset, n)));
  }
  return FinishUpload(digest);
}

absl::StatusOr<std::string> S3BlobStore::Read(const Digest& digest, int64_t offset, int64_t limit) {
  RETURN_IF_ERROR(ValidateDigest(digest));
  if (offset < 0 || limit < 0 || offset > digest.size_bytes)
    return absl::OutOfRangeError(absl::StrCat("blob ", digest.ToString(), ": read offset ", offset,
                                              " / limit ", limit, " out of range"));
  int64_t count = digest.size_bytes - offset;
  if (limit > 0) count = std::min(count, limit);
  const absl::Status not_found =
      absl::NotFoundError(absl::StrCat("blob ", digest.ToString(), " is not in the store"));
  if (count == 0) {
    ASSIGN_OR_RETURN(bool present, Contains(digest));
    if (!present) return not_found;
    return std::string();
  }
  absl::StatusOr<std::string> bytes = client_->GetObject(BlobKey(digest), offset, count);
  if (absl::IsNotFound(bytes.status())) return not_found;
  if (!bytes.ok()) return bytes.status();
  if (static_cast<int64_t>(bytes->size()) != count)
    return absl::DataLossError(absl::StrCat("blob ", digest.ToString(), ": S3 returned ",
                                            bytes->size(), " bytes of ", count, " asked"));
  if (options_.verify_reads && offset == 0 && count == digest.size_bytes &&
      ComputeDigest(*bytes).hash != digest.hash)
    return absl::DataLossError(absl::StrCat("blob ", digest.ToString(), " is corrupt in S3"));
  return bytes;
}

std::shared_ptr<S3BlobStore::Upload> S3BlobStore::GetUpload(const std::string& key) {
  std::lock_guard<std::mutex> lock(uploads_mutex_);
  auto it = uploads_.find(key);
  if (it != uploads_.end()) return it->second;
  if (uploads_.size() >= kMaxTrackedUploads) {
    // Forget idle uploads without a buffer: their state is in S3 and is reloaded on demand.
    for (auto i = uploads_.begin(); i != uploads_.end();) {
      std::unique_lock<std::mutex> try_lock(i->second->mutex, std::try_to_lock);
      const bool idle =
          try_lock.owns_lock() && i->second->buffer.empty() && i->second.use_count() == 1;
      if (try_lock.owns_lock()) try_lock.unlock();
      i = idle ? uploads_.erase(i) : std::next(i);
    }
  }
  auto upload = std::make_shared<Upload>();
  upload->key = key;
  return uploads_[key] = upload;
}

void S3BlobStore::Forget(const std::string& key) {
  std::lock_guard<std::mutex> lock(uploads_mutex_);
  uploads_.erase(key);
  buffered_.remove(key);
}

void S3BlobStore::NoteBuffered(const std::string& key) {
  std::lock_guard<std::mutex> lock(uploads_mutex_);
  buffered_.remove(key);
  buffered_.push_back(key);
  // Bound the memory of buffers: the oldest upload loses its unsent bytes (its client is told
  // where to resume on its next append). An upload busy right now is skipped.
  while (static_cast<int>(buffered_.size()) > s3_options_.max_buffered_uploads) {
    const std::string oldest = buffered_.front();
    buffered_.pop_front();
    auto it = uploads_.find(oldest);
    if (it == uploads_.end() || oldest == key) continue;
    std::unique_lock<std::mutex> try_lock(it->second->mutex, std::try_to_lock);
    if (try_lock.owns_lock()) {
      it->second->buffer.clear();
      it->second->buffer.shrink_to_fit();
    }
  }
}

absl::Status S3BlobStore::Load(const Digest& digest, Upload& upload) {
  if (upload.loaded) return absl::OkStatus();
  const std::string& key = upload.key;
  ASSIGN_OR_RETURN(std::optional<int64_t> assembled, client_->HeadObject(key));
  upload.assembled = assembled.has_value() && *assembled == digest.size_bytes;
  if (!upload.assembled) {
    ASSIGN_OR_RETURN(std::vector<S3Client::Upload> found, client_->ListMultipartUploads(key));
    // Several uploads of one blob (two clients at once): continue the one furthest along.
    for (const S3Client::Upload& u : found) {
      if (u.key != key) continue;
      ASSIGN_OR_RETURN(std::vector<S3Client::Part> parts, client_->ListParts(key, u.upload_id));
      std::vector<S3Client::Part> full;  // the contiguous run of full parts 1..n
      for (const S3Client::Part& p : parts) {
        if (p.number != static_cast<int>(full.size()) + 1 || p.size != s3_options_.part_bytes)
          break;
        full.push_back(p);
      }
      if (upload.upload_id.empty() || full.size() > upload.parts.size()) {
        upload.upload_id = u.upload_id;
        upload.parts = std::move(full);
      }
    }
  }
  upload.loaded = true;
  return absl::OkStatus();
}

absl::Status S3BlobStore::SendFullParts(Upload& upload) {
  const std::string& key = upload.key;
  size_t sent = 0;
  while (static_cast<int64_t>(upload.buffer.size() - sent) >= s3_options_.part_bytes) {
    if (upload.upload_id.empty()) {
      ASSIGN_OR_RETURN(upload.upload_id, client_->CreateMultipartUpload(key));
    }
    const int number = static_cast<int>(upload.parts.size()) + 1;
    const absl::string_view part =
        absl::string_view(upload.buffer).substr(sent, static_cast<size_t>(s3_options_.part_bytes));
    absl::StatusOr<std::string> etag = client_->UploadPart(key, upload.upload_id, number, part);
    if (!etag.ok()) {
      upload.buffer.erase(0, sent);
      return etag.status();
    }
    upload.parts.push_back({number, *etag, s3_options_.part_bytes});
    sent += part.size();
  }
  upload.buffer.erase(0, sent);
  return absl::OkStatus();
}

absl::StatusOr<int64_t> S3BlobStore::CommittedSize(const Digest& digest) {
  RETURN_IF_ERROR(ValidateDigest(digest));
  ASSIGN_OR_RETURN(bool present, Contains(digest));
  if (present) return digest.size_bytes;
  return PartSize(digest, "");
}

absl::StatusOr<int64_t> S3BlobStore::PartSize(const Digest& digest, const std::string& space) {
  std::shared_ptr<Upload> upload = GetUpload(UploadKey(digest, space));
  std::lock_guard<std::mutex> lock(upload->mutex);
  RETURN_IF_ERROR(Load(digest, *upload));
  if (upload->assembled) return digest.size_bytes;
  return upload->durable() + static_cast<int64_t>(upload->buffer.size());
}

absl::StatusOr<int64_t> S3BlobStore::Append(const Digest& digest, int64_t offset,
                                            absl::string_view data) {
  return AppendPart(digest, "", offset, data);
}

absl::StatusOr<int64_t> S3BlobStore::AppendPart(const Digest& digest, const std::string& space,
                                                int64_t offset, absl::string_view data) {
  RETURN_IF_ERROR(CheckWritable(digest, options_));
  std::shared_ptr<Upload> upload = GetUpload(UploadKey(digest, space));
  {
    std::lock_guard<std::mutex> lock(upload->mutex);
    if (!upload->loaded) {  // the first append of this process: not on every chunk
      if (space.empty()) {
        ASSIGN_OR_RETURN(bool present, Contains(digest));
        if (present) return digest.size_bytes;
      }
      RETURN_IF_ERROR(Load(digest, *upload));
    }
    if (upload->assembled) return digest.size_bytes;
    const int64_t durable = upload->durable();
    const int64_t committed = durable + static_cast<int64_t>(upload->buffer.size());
    if (offset == durable && offset != committed) {
      upload->buffer.clear();  // a restarted client resends what was only buffered
    } else if (offset != committed) {
      return absl::FailedPreconditionError(
          absl::StrCat("blob ", digest.ToString(), ": write at offset ", offset,
                       " but the upload has ", committed, " bytes committed (resume there)"));
    }
    if (offset + static_cast<int64_t>(data.size()) > digest.size_bytes)
      return absl::InvalidArgumentError(absl::StrCat("blob ", digest.ToString(), ": ",
                                                     offset + static_cast<int64_t>(data.size()),
                                                     " bytes sent, more than the digest's size"));
    upload->buffer.append(data.data(), data.size());
    RETURN_IF_ERROR(SendFullParts(*upload));
    if (upload->buffer.empty()) return offset + static_cast<int64_t>(data.size());
  }
  NoteBuffered(upload->key);
  return offset + static_cast<int64_t>(data.size());
}

absl::Status S3BlobStore::Assemble(const Digest& digest, Upload& upload) {
  const std::string& key = upload.key;
  const int64_t committed = upload.durable() + static_cast<int64_t>(upload.buffer.size());
  if (committed != digest.size_bytes)
    return absl::FailedPreconditionError(absl::StrCat("blob ", digest.ToString(),
                                                      ": upload incomplete, ", committed, " of ",
                                                      digest.size_bytes, " bytes committed"));
  if (upload.upload_id.empty()) {
    RETURN_IF_ERROR(client_->PutObject(key, upload.buffer));  // smaller than one part
  } else {
    if (!upload.buffer.empty()) {
      const int number = static_cast<int>(upload.parts.size()) + 1;
      ASSIGN_OR_RETURN(std::string etag,
                       client_->UploadPart(key, upload.upload_id, number, upload.buffer));
      upload.parts.push_back({number, etag, static_cast<int64_t>(upload.buffer.size())});
    }
    RETURN_IF_ERROR(client_->CompleteMultipartUpload(key, upload.upload_id, upload.parts));
  }
  upload.buffer.clear();
  upload.parts.clear();
  upload.upload_id.clear();
  upload.assembled = true;
  return absl::OkStatus();
}

absl::Status S3BlobStore::CopyToBlob(const std::string& from, const Digest& digest) {
  const std::string to = BlobKey(digest);
  if (digest.size_bytes <= s3_options_.copy_part_bytes) return client_->CopyObject(from, to);
  ASSIGN_OR_RETURN(std::string id, client_->CreateMultipartUpload(to));
  std::vector<S3Client::Part> parts;
  for (int64_t first = 0; first < digest.size_bytes; first += s3_options_.copy_part_bytes) {
    const int64_t last = std::min(digest.size_bytes, first + s3_options_.copy_part_bytes) - 1;
    const int number = static_cast<int>(parts.size()) + 1;
    absl::StatusOr<std::string> etag = client_->UploadPartCopy(to, id, number, from, first, last);
    if (!etag.ok()) {
      (void)client_->AbortMultipartUpload(to, id);
      return etag.status();
    }
    parts.push_back({number, *etag, last - first + 1});
  }
  absl::Status s = client_->CompleteMultipartUpload(to, id, parts);
  if (!s.ok()) (void)client_->AbortMultipartUpload(to, id);
  return s;
}

absl::Status S3BlobStore::VerifyAndPublish(const Digest& digest, const std::string& key) {
  Sha256 sha;
  int64_t size = 0;
  for (;;) {
    ASSIGN_OR_RETURN(std::string chunk,
                     client_->GetObject(key, size, s3_options_.verify_chunk_bytes));
    sha.Update(chunk);
    size += static_cast<int64_t>(chunk.size());
    if (static_cast<int64_t>(chunk.size()) < s3_options_.verify_chunk_bytes ||
        size >= digest.size_bytes)
      break;
  }
  const Digest actual{sha.HexDigest(), size};
  if (actual != digest) {
    RETURN_IF_ERROR(client_->DeleteObject(key));  // a wrong upload is never kept
    return absl::InvalidArgumentError(absl::StrCat("digest mismatch: claimed ", digest.ToString(),
                                                   ", uploaded bytes are ", actual.ToString(),
                                                   "; upload discarded"));
  }
  ASSIGN_OR_RETURN(bool present, Contains(digest));  // a tenant's proof of a blob already here
  if (!present) RETURN_IF_ERROR(CopyToBlob(key, digest));
  return client_->DeleteObject(key);
}

absl::Status S3BlobStore::FinishUpload(const Digest& digest) {
  RETURN_IF_ERROR(CheckWritable(digest, options_));
  ASSIGN_OR_RETURN(bool present, Contains(digest));
  if (present) {
    Forget(UploadKey(digest, ""));
    return absl::OkStatus();
  }
  return FinishPart(digest, "");
}

absl::Status S3BlobStore::FinishPart(const Digest& digest, const std::string& space) {
  const std::string key = UploadKey(digest, space);
  std::shared_ptr<Upload> upload = GetUpload(key);
  absl::Status status;
  {
    std::lock_guard<std::mutex> lock(upload->mutex);
    RETURN_IF_ERROR(Load(digest, *upload));
    if (!upload->assembled) RETURN_IF_ERROR(Assemble(digest, *upload));
    status = VerifyAndPublish(digest, key);
    if (!status.ok() && !absl::IsInvalidArgument(status)) return status;  // retry later
  }
  Forget(key);
  return status;
}

absl::Status S3BlobStore::Grant(const std::string& tenant, const std::vector<Digest>& digests) {
  RETURN_IF_ERROR(CheckTenantName(tenant));
  for (const Digest& d : digests) {
    RETURN_IF_ERROR(ValidateDigest(d));
    ASSIGN_OR_RETURN(bool present, Contains(d));
    if (!present)
      return absl::FailedPreconditionError(
          absl::StrCat("blob ", d.ToString(), " is not in the store: nothing to grant"));
    RETURN_IF_ERROR(client_->PutObject(GrantKey(tenant, d), ""));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::vector<Digest>> S3BlobStore::FindUngranted(const std::string& tenant,
                                                               const std::vector<Digest>& digests) {
  RETURN_IF_ERROR(CheckTenantName(tenant));
  std::vector<Digest> out;
  for (const Digest& d : digests) {
    RETURN_IF_ERROR(ValidateDigest(d));
    ASSIGN_OR_RETURN(std::optional<int64_t> grant, client_->HeadObject(GrantKey(tenant, d)));
    bool granted = grant.has_value();
    if (granted) {
      ASSIGN_OR_RETURN(granted, Contains(d));
    }
    if (!granted) out.push_back(d);
  }
  return out;
}

absl::StatusOr<int64_t> S3BlobStore::TenantCommittedSize(const std::string& tenant,
                                                         const Digest& digest) {
  ASSIGN_OR_RETURN(std::vector<Digest> ungranted, FindUngranted(tenant, {digest}));
  if (ungranted.empty()) return digest.size_bytes;
  return PartSize(digest, tenant);
}

absl::StatusOr<int64_t> S3BlobStore::TenantAppend(const std::string& tenant, const Digest& digest,
                                                  int64_t offset, absl::string_view data) {
  RETURN_IF_ERROR(CheckTenantName(tenant));
  if (offset == 0) {  // a new upload of a blob already the tenant's stages nothing
    ASSIGN_OR_RETURN(std::vector<Digest> ungranted, FindUngranted(tenant, {digest}));
    if (ungranted.empty()) return digest.size_bytes;
  }
  return AppendPart(digest, tenant, offset, data);
}

absl::Status S3BlobStore::TenantFinishUpload(const std::string& tenant, const Digest& digest) {
  ASSIGN_OR_RETURN(std::vector<Digest> ungranted, FindUngranted(tenant, {digest}));
  if (ungranted.empty()) return absl::OkStatus();
  RETURN_IF_ERROR(CheckWritable(digest, options_));
  RETURN_IF_ERROR(FinishPart(digest, tenant));
  return Grant(tenant, {digest});
}

absl::StatusOr<StoreStats> S3BlobStore::Stats() {
  ASSIGN_OR_RETURN(std::vector<S3Client::Object> objects,
                   client_->ListObjects(absl::StrCat(client_->location().prefix, "cas/")));
  StoreStats stats;
  for (const S3Client::Object& o : objects) {
    ++stats.blob_count;
    stats.total_bytes += o.size;
  }
  return stats;
}

}  // namespace instascene::store
