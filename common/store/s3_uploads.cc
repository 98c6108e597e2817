// The resumable uploads of S3BlobStore (s3_blob_store.h): each upload is a multipart upload in
// S3 (its state reloaded from S3 on demand, so an upload resumes across restarts), appended in
// parts, assembled, verified against its digest and published under the blob's key.
#include "common/store/s3_blob_store.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"

namespace instascene::store {
namespace {

constexpr size_t kMaxTrackedUploads = 4096;

}  // namespace

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
    if (offset == durable && upload->buffer.size() > 0) {
      upload->buffer.clear();  // a restarted client resends what was only buffered
    }
    RETURN_IF_ERROR(CheckAppend(
        digest, offset, durable + static_cast<int64_t>(upload->buffer.size()), data.size()));
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

}  // namespace instascene::store
