// FilesystemBlobStore (blob_store.h): blobs under <root>/cas by digest, resumable uploads as
// part files under <root>/uploads (expired after upload_ttl_seconds), temp files under <root>/tmp
// published by rename, tenant grants as marker files; one process per root (a file lock).
#include "common/store/blob_store.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <vector>

#include "absl/strings/str_cat.h"
#include "common/core/file_io.h"
#include "common/core/status.h"

namespace instascene::store {
namespace fs = std::filesystem;

absl::StatusOr<std::unique_ptr<FilesystemBlobStore>> FilesystemBlobStore::Open(
    const std::string& root, const StoreOptions& options) {
  RETURN_IF_ERROR(options.Validate());
  std::error_code ec;
  for (const char* sub : {"cas", "uploads", "tmp"}) {
    fs::create_directories(fs::path(root) / sub, ec);
    if (ec) return absl::UnavailableError(absl::StrCat(root, "/", sub, ": ", ec.message()));
  }
  ASSIGN_OR_RETURN(FileLock lock,
                   FileLock::Acquire((fs::path(root) / ".lock").string(), "store " + root));
  // Temp files of writes interrupted by a crash were never published: drop them.
  for (const auto& entry : fs::directory_iterator(fs::path(root) / "tmp", ec)) {
    fs::remove(entry.path(), ec);
  }
  std::unique_ptr<FilesystemBlobStore> store(
      new FilesystemBlobStore(root, options, std::move(lock)));
  store->ExpireUploads(/*force=*/true);
  return store;
}

void FilesystemBlobStore::ExpireUploads(bool force) {
  if (options_.upload_ttl_seconds <= 0) return;
  const auto now = fs::file_time_type::clock::now();
  const int64_t now_ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                             std::chrono::steady_clock::now().time_since_epoch())
                             .count();
  int64_t last = last_sweep_ms_.load();
  if (!force && (now_ms - last < 60'000 || !last_sweep_ms_.compare_exchange_strong(last, now_ms)))
    return;
  last_sweep_ms_ = now_ms;
  const auto cutoff = now - std::chrono::seconds(options_.upload_ttl_seconds);
  std::lock_guard<std::mutex> lock(upload_mutex_);  // never under an Append in progress
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(fs::path(root_) / "uploads", ec)) {
    std::error_code e;
    if (entry.path().extension() != ".part" || !entry.is_regular_file(e)) continue;
    const auto written = entry.last_write_time(e);
    if (!e && written < cutoff && fs::remove(entry.path(), e)) ++expired_uploads_;
  }
}

std::string FilesystemBlobStore::BlobPath(const Digest& digest) const {
  return (fs::path(root_) / "cas" / digest.hash.substr(0, 2) / digest.hash).string();
}

std::string FilesystemBlobStore::PartPath(const Digest& digest, const std::string& space) const {
  return (fs::path(root_) / "uploads" /
          absl::StrCat(space, space.empty() ? "" : ".", digest.hash, "-", digest.size_bytes,
                       ".part"))
      .string();
}

std::string FilesystemBlobStore::GrantPath(const std::string& tenant, const Digest& digest) const {
  return (fs::path(root_) / "grants" / tenant / digest.hash.substr(0, 2) /
          absl::StrCat(digest.hash, "-", digest.size_bytes))
      .string();
}

bool FilesystemBlobStore::Contains(const Digest& digest) const {
  std::error_code ec;
  const auto size = fs::file_size(BlobPath(digest), ec);
  return !ec && static_cast<int64_t>(size) == digest.size_bytes;
}

absl::StatusOr<std::vector<Digest>> FilesystemBlobStore::FindMissing(
    const std::vector<Digest>& digests) {
  std::vector<Digest> missing;
  for (const Digest& d : digests) {
    RETURN_IF_ERROR(ValidateDigest(d));
    if (Contains(d)) {
      Touch(d);  // about to be referenced: young for the garbage collector's grace period
    } else {
      missing.push_back(d);
    }
  }
  return missing;
}

void FilesystemBlobStore::Touch(const Digest& digest) const {
  std::error_code ec;  // best effort: a failed touch only shortens the blob's grace
  fs::last_write_time(BlobPath(digest), fs::file_time_type::clock::now(), ec);
}

absl::Status FilesystemBlobStore::Publish(const std::string& from, const Digest& digest) {
  const fs::path target = BlobPath(digest);
  std::error_code ec;
  fs::create_directories(target.parent_path(), ec);
  if (ec)
    return absl::UnavailableError(absl::StrCat(target.parent_path().string(), ": ", ec.message()));
  absl::Status s = RenameDurably(from, target.string());
  if (!s.ok()) fs::remove(from, ec);
  return s;
}

absl::Status FilesystemBlobStore::Put(const Digest& digest, absl::string_view bytes) {
  RETURN_IF_ERROR(CheckWritable(digest, options_));
  RETURN_IF_ERROR(VerifyBlobBytes(digest, bytes));
  if (Contains(digest)) {
    Touch(digest);
    return absl::OkStatus();
  }
  std::string temp;
  {
    std::lock_guard<std::mutex> lock(temp_mutex_);
    temp =
        (fs::path(root_) / "tmp" / absl::StrCat(digest.hash, ".", ::getpid(), ".", temp_counter_++))
            .string();
  }
  absl::Status s = WriteAndSync(temp, bytes);
  if (!s.ok()) {
    std::error_code ec;
    fs::remove(temp, ec);
    return s;
  }
  return Publish(temp, digest);
}

absl::StatusOr<std::string> FilesystemBlobStore::Read(const Digest& digest, int64_t offset,
                                                      int64_t limit) {
  RETURN_IF_ERROR(ValidateDigest(digest));
  if (offset < 0 || limit < 0 || offset > digest.size_bytes)
    return absl::OutOfRangeError(absl::StrCat("blob ", digest.ToString(), ": read offset ", offset,
                                              " / limit ", limit, " out of range"));
  const std::string path = BlobPath(digest);
  std::ifstream in(path, std::ios::binary);
  if (!in || !Contains(digest))
    return absl::NotFoundError(absl::StrCat("blob ", digest.ToString(), " is not in the store"));
  int64_t count = digest.size_bytes - offset;
  if (limit > 0) count = std::min(count, limit);
  std::string bytes(static_cast<size_t>(count), '\0');
  in.seekg(offset);
  in.read(bytes.data(), count);
  if (in.gcount() != count)
    return absl::DataLossError(absl::StrCat("blob ", digest.ToString(), ": short read at ", path));
  if (options_.verify_reads && offset == 0 && count == digest.size_bytes &&
      ComputeDigest(bytes).hash != digest.hash)
    return absl::DataLossError(absl::StrCat("blob ", digest.ToString(), " is corrupt on disk"));
  return bytes;
}

absl::StatusOr<int64_t> FilesystemBlobStore::CommittedSize(const Digest& digest) {
  RETURN_IF_ERROR(ValidateDigest(digest));
  if (Contains(digest)) return digest.size_bytes;
  ExpireUploads(/*force=*/false);  // an upload (re)starts here: a good moment to sweep
  std::error_code ec;
  const auto size = fs::file_size(PartPath(digest), ec);
  return ec ? 0 : static_cast<int64_t>(size);
}

absl::StatusOr<int64_t> FilesystemBlobStore::Append(const Digest& digest, int64_t offset,
                                                    absl::string_view data) {
  return AppendPart(digest, "", offset, data);
}

absl::StatusOr<int64_t> FilesystemBlobStore::AppendPart(const Digest& digest,
                                                        const std::string& space, int64_t offset,
                                                        absl::string_view data) {
  RETURN_IF_ERROR(CheckWritable(digest, options_));
  std::lock_guard<std::mutex> lock(upload_mutex_);
  if (space.empty() && Contains(digest)) return digest.size_bytes;
  const std::string part = PartPath(digest, space);
  std::error_code ec;
  const auto existing = fs::file_size(part, ec);
  const int64_t committed = ec ? 0 : static_cast<int64_t>(existing);
  RETURN_IF_ERROR(CheckAppend(digest, offset, committed, data.size()));
  std::ofstream out(part, std::ios::binary | std::ios::app);
  out.write(data.data(), static_cast<std::streamsize>(data.size()));
  out.flush();
  if (!out)
    return absl::UnavailableError(absl::StrCat("upload of ", digest.ToString(), ": write failed"));
  return committed + static_cast<int64_t>(data.size());
}

absl::Status FilesystemBlobStore::FinishUpload(const Digest& digest) {
  return FinishPart(digest, "");
}

absl::Status FilesystemBlobStore::FinishPart(const Digest& digest, const std::string& space) {
  RETURN_IF_ERROR(CheckWritable(digest, options_));
  std::lock_guard<std::mutex> lock(upload_mutex_);
  if (space.empty() && Contains(digest)) return absl::OkStatus();
  const std::string part = PartPath(digest, space);
  std::error_code size_ec;
  const auto part_size = fs::file_size(part, size_ec);
  const int64_t committed = size_ec ? 0 : static_cast<int64_t>(part_size);
  if (committed != digest.size_bytes)  // keep it: the client may resume
    return absl::FailedPreconditionError(absl::StrCat("blob ", digest.ToString(),
                                                      ": upload incomplete, ", committed, " of ",
                                                      digest.size_bytes, " bytes committed"));
  ASSIGN_OR_RETURN(Digest actual, DigestFile(part));
  std::error_code ec;
  if (actual != digest) {
    fs::remove(part, ec);  // a wrong upload is never kept, not even to resume
    return absl::InvalidArgumentError(absl::StrCat("digest mismatch: claimed ", digest.ToString(),
                                                   ", uploaded bytes are ", actual.ToString(),
                                                   "; upload discarded"));
  }
  if (Contains(digest)) {  // a tenant proved it holds a blob the store has: nothing to publish
    fs::remove(part, ec);
    return absl::OkStatus();
  }
  RETURN_IF_ERROR(SyncPath(part, /*directory=*/false));
  return Publish(part, digest);
}

absl::Status FilesystemBlobStore::Grant(const std::string& tenant,
                                        const std::vector<Digest>& digests) {
  RETURN_IF_ERROR(CheckTenantName(tenant));
  for (const Digest& d : digests) {
    RETURN_IF_ERROR(ValidateDigest(d));
    if (!Contains(d))
      return absl::FailedPreconditionError(
          absl::StrCat("blob ", d.ToString(), " is not in the store: nothing to grant"));
    const fs::path path = GrantPath(tenant, d);
    std::error_code ec;
    if (fs::exists(path, ec)) continue;
    fs::create_directories(path.parent_path(), ec);
    // Not fsynced: a grant lost in a crash costs the tenant an upload, never exposes a blob.
    std::ofstream touch(path, std::ios::binary);
    if (!touch)
      return absl::UnavailableError(absl::StrCat("grant of ", d.ToString(), ": cannot write"));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::vector<Digest>> FilesystemBlobStore::FindUngranted(
    const std::string& tenant, const std::vector<Digest>& digests) {
  RETURN_IF_ERROR(CheckTenantName(tenant));
  std::vector<Digest> out;
  for (const Digest& d : digests) {
    RETURN_IF_ERROR(ValidateDigest(d));
    std::error_code ec;
    if (!fs::exists(GrantPath(tenant, d), ec) || !Contains(d)) out.push_back(d);
  }
  return out;
}

absl::StatusOr<int64_t> FilesystemBlobStore::TenantCommittedSize(const std::string& tenant,
                                                                 const Digest& digest) {
  RETURN_IF_ERROR(ValidateDigest(digest));
  ASSIGN_OR_RETURN(std::vector<Digest> ungranted, FindUngranted(tenant, {digest}));
  if (ungranted.empty()) return digest.size_bytes;
  ExpireUploads(/*force=*/false);
  std::error_code ec;
  const auto size = fs::file_size(PartPath(digest, tenant), ec);
  return ec ? 0 : static_cast<int64_t>(size);
}

absl::StatusOr<int64_t> FilesystemBlobStore::TenantAppend(const std::string& tenant,
                                                          const Digest& digest, int64_t offset,
                                                          absl::string_view data) {
  RETURN_IF_ERROR(CheckTenantName(tenant));
  if (offset == 0) {  // a new upload of a blob already the tenant's stages nothing
    ASSIGN_OR_RETURN(std::vector<Digest> ungranted, FindUngranted(tenant, {digest}));
    if (ungranted.empty()) return digest.size_bytes;
  }
  return AppendPart(digest, tenant, offset, data);
}

absl::Status FilesystemBlobStore::TenantFinishUpload(const std::string& tenant,
                                                     const Digest& digest) {
  ASSIGN_OR_RETURN(std::vector<Digest> ungranted, FindUngranted(tenant, {digest}));
  if (ungranted.empty()) return absl::OkStatus();
  RETURN_IF_ERROR(FinishPart(digest, tenant));
  return Grant(tenant, {digest});
}

absl::StatusOr<StoreStats> FilesystemBlobStore::Stats() {
  StoreStats stats;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(fs::path(root_) / "cas", ec);
       it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (ec) break;
    if (it->is_regular_file(ec)) {
      ++stats.blob_count;
      stats.total_bytes += static_cast<int64_t>(it->file_size(ec));
    }
  }
  for (const auto& entry : fs::directory_iterator(fs::path(root_) / "uploads", ec)) {
    std::error_code e;
    if (entry.path().extension() != ".part" || !entry.is_regular_file(e)) continue;
    ++stats.partial_uploads;
    stats.partial_bytes += static_cast<int64_t>(entry.file_size(e));
  }
  stats.expired_uploads = expired_uploads_.load();
  return stats;
}

namespace {
std::chrono::system_clock::time_point ToSystemTime(fs::file_time_type t) {
  return std::chrono::time_point_cast<std::chrono::system_clock::duration>(
      std::chrono::file_clock::to_sys(t));
}
}  // namespace

absl::StatusOr<std::vector<StoredBlob>> FilesystemBlobStore::ListBlobs() {
  std::vector<StoredBlob> blobs;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(fs::path(root_) / "cas", ec);
       it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (ec) break;
    if (!it->is_regular_file(ec)) continue;
    StoredBlob b;
    b.digest.hash = it->path().filename().string();
    b.digest.size_bytes = static_cast<int64_t>(it->file_size(ec));
    if (ec || !ValidateDigest(b.digest).ok()) continue;  // not a blob (nothing else lives there)
    const fs::file_time_type modified = it->last_write_time(ec);
    if (ec) continue;
    b.modified = ToSystemTime(modified);
    blobs.push_back(std::move(b));
  }
  if (ec) return absl::UnavailableError(absl::StrCat(root_, "/cas: ", ec.message()));
  std::sort(blobs.begin(), blobs.end(),
            [](const StoredBlob& a, const StoredBlob& b) { return a.digest.hash < b.digest.hash; });
  return blobs;
}

absl::StatusOr<int64_t> FilesystemBlobStore::TenantBytes(const std::string& tenant) {
  RETURN_IF_ERROR(CheckTenantName(tenant));
  int64_t total = 0;
  std::error_code ec;
  const fs::path folder = fs::path(root_) / "grants" / tenant;
  if (!fs::exists(folder, ec)) return total;
  for (auto it = fs::recursive_directory_iterator(folder, ec);
       it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (ec) break;
    if (!it->is_regular_file(ec)) continue;
    ASSIGN_OR_RETURN(const int64_t size, GrantNameBytes(it->path().filename().string()));
    total += size;
  }
  if (ec) return absl::UnavailableError(absl::StrCat(folder.string(), ": ", ec.message()));
  return total;
}

absl::StatusOr<std::optional<std::chrono::system_clock::time_point>>
FilesystemBlobStore::BlobModified(const Digest& digest) {
  RETURN_IF_ERROR(ValidateDigest(digest));
  std::error_code ec;
  const fs::file_time_type modified = fs::last_write_time(BlobPath(digest), ec);
  if (ec == std::errc::no_such_file_or_directory)
    return std::optional<std::chrono::system_clock::time_point>();
  if (ec) return absl::UnavailableError(absl::StrCat(BlobPath(digest), ": ", ec.message()));
  return std::optional(ToSystemTime(modified));
}

absl::Status FilesystemBlobStore::Remove(const Digest& digest) {
  RETURN_IF_ERROR(ValidateDigest(digest));
  std::error_code ec;
  fs::remove(BlobPath(digest), ec);
  if (ec) return absl::UnavailableError(absl::StrCat(BlobPath(digest), ": ", ec.message()));
  return absl::OkStatus();
}

absl::StatusOr<std::vector<StoredGrant>> FilesystemBlobStore::ListGrants() {
  std::vector<StoredGrant> grants;
  std::error_code ec;
  const fs::path folder = fs::path(root_) / "grants";
  if (!fs::exists(folder, ec)) return grants;
  // grants/<tenant>/<hash[0:2]>/<hash>-<size>: anything else there is not a grant.
  for (auto it = fs::recursive_directory_iterator(folder, ec);
       it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (ec) break;
    if (it.depth() != 2 || !it->is_regular_file(ec)) continue;
    const fs::path& path = it->path();
    std::optional<Digest> digest = GrantNameDigest(path.filename().string());
    const std::string tenant = path.parent_path().parent_path().filename().string();
    if (!digest.has_value() || !CheckTenantName(tenant).ok()) continue;
    const fs::file_time_type modified = it->last_write_time(ec);
    if (ec) continue;
    grants.push_back({tenant, std::move(*digest), ToSystemTime(modified)});
  }
  if (ec) return absl::UnavailableError(absl::StrCat(folder.string(), ": ", ec.message()));
  std::sort(grants.begin(), grants.end(), GrantOrder);
  return grants;
}

absl::Status FilesystemBlobStore::RemoveGrant(const std::string& tenant, const Digest& digest) {
  RETURN_IF_ERROR(CheckTenantName(tenant));
  RETURN_IF_ERROR(ValidateDigest(digest));
  std::error_code ec;
  fs::remove(GrantPath(tenant, digest), ec);
  if (ec)
    return absl::UnavailableError(absl::StrCat(GrantPath(tenant, digest), ": ", ec.message()));
  return absl::OkStatus();
}

}  // namespace instascene::store
