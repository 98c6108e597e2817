#include "services/store/remote_blob_store.h"

#include <fstream>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/rpc/status.h"

namespace instascene::store_service {

using rpc::FromGrpcStatus;

namespace {
constexpr int64_t kChunk = 1 << 20;
}

// Fails fast, before any byte is sent, on blobs the server will refuse (its limit is known from
// GetStoreInfo); the server checks again.
absl::Status RemoteBlobStore::CheckSize(const store::Digest& digest) const {
  if (digest.size_bytes > options_.max_blob_bytes)
    return absl::ResourceExhaustedError(absl::StrCat("blob ", digest.ToString(),
                                                     " is larger than the store's limit of ",
                                                     options_.max_blob_bytes, " bytes"));
  return absl::OkStatus();
}

absl::StatusOr<std::unique_ptr<RemoteBlobStore>> RemoteBlobStore::Connect(
    std::shared_ptr<grpc::Channel> channel, int timeout_ms) {
  std::unique_ptr<RemoteBlobStore> store(
      new RemoteBlobStore(v1::ContentStore::NewStub(std::move(channel))));
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(timeout_ms));
  context.set_wait_for_ready(true);
  v1::GetStoreInfoResponse info;
  RETURN_IF_ERROR(Annotate(
      FromGrpcStatus(store->stub_->GetStoreInfo(&context, v1::GetStoreInfoRequest(), &info)),
      "store"));
  store->options_.max_blob_bytes = info.max_blob_bytes();
  store->options_.max_batch_bytes = info.max_batch_bytes();
  return store;
}

absl::StatusOr<std::vector<store::Digest>> RemoteBlobStore::FindMissing(
    const std::vector<store::Digest>& digests) {
  std::vector<store::Digest> missing;
  constexpr size_t kPerCall = 10000;
  for (size_t b = 0; b < digests.size(); b += kPerCall) {
    v1::FindMissingBlobsRequest request;
    for (size_t i = b; i < std::min(digests.size(), b + kPerCall); ++i)
      rpc::ToProto(digests[i], request.add_digests());
    v1::FindMissingBlobsResponse response;
    grpc::ClientContext context;
    RETURN_IF_ERROR(FromGrpcStatus(stub_->FindMissingBlobs(&context, request, &response)));
    for (const auto& d : response.missing()) missing.push_back(rpc::FromProto(d));
  }
  return missing;
}

absl::Status RemoteBlobStore::Grant(const std::string& tenant,
                                    const std::vector<store::Digest>& digests) {
  constexpr size_t kPerCall = 10000;
  for (size_t b = 0; b < digests.size(); b += kPerCall) {
    v1::GrantBlobsRequest request;
    request.set_tenant(tenant);
    for (size_t i = b; i < std::min(digests.size(), b + kPerCall); ++i)
      rpc::ToProto(digests[i], request.add_digests());
    v1::GrantBlobsResponse response;
    grpc::ClientContext context;
    RETURN_IF_ERROR(FromGrpcStatus(stub_->GrantBlobs(&context, request, &response)));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::vector<store::Digest>> RemoteBlobStore::FindUngranted(
    const std::string& tenant, const std::vector<store::Digest>& digests) {
  std::vector<store::Digest> out;
  constexpr size_t kPerCall = 10000;
  for (size_t b = 0; b < digests.size(); b += kPerCall) {
    v1::FindUngrantedBlobsRequest request;
    request.set_tenant(tenant);
    for (size_t i = b; i < std::min(digests.size(), b + kPerCall); ++i)
      rpc::ToProto(digests[i], request.add_digests());
    v1::FindUngrantedBlobsResponse response;
    grpc::ClientContext context;
    RETURN_IF_ERROR(FromGrpcStatus(stub_->FindUngrantedBlobs(&context, request, &response)));
    for (const auto& d : response.ungranted()) out.push_back(rpc::FromProto(d));
  }
  return out;
}

absl::Status RemoteBlobStore::Put(const store::Digest& digest, absl::string_view bytes) {
  RETURN_IF_ERROR(CheckSize(digest));
  if (static_cast<int64_t>(bytes.size()) <= options_.max_batch_bytes) {
    v1::BatchUpdateBlobsRequest request;
    auto* blob = request.add_blobs();
    rpc::ToProto(digest, blob->mutable_digest());
    blob->set_data(std::string(bytes));
    v1::BatchUpdateBlobsResponse response;
    grpc::ClientContext context;
    RETURN_IF_ERROR(FromGrpcStatus(stub_->BatchUpdateBlobs(&context, request, &response)));
    if (response.statuses_size() != 1) return absl::InternalError("store: bad batch reply");
    const auto& s = response.statuses(0);
    return absl::Status(static_cast<absl::StatusCode>(s.code()), s.message());
  }
  int64_t sent = 0;
  return WriteStream(
             digest, 0,
             [&]() -> absl::StatusOr<std::string> {
               const int64_t n =
                   std::min<int64_t>(kChunk, static_cast<int64_t>(bytes.size()) - sent);
               std::string chunk(bytes.substr(static_cast<size_t>(sent), static_cast<size_t>(n)));
               sent += n;
               return chunk;
             },
             true, nullptr)
      .status();
}

absl::StatusOr<int64_t> RemoteBlobStore::WriteStream(
    const store::Digest& digest, int64_t offset,
    const std::function<absl::StatusOr<std::string>()>& next, bool finish,
    const store::TransferProgress& progress) {
  grpc::ClientContext context;
  v1::WriteResponse response;
  std::unique_ptr<grpc::ClientWriter<v1::WriteRequest>> writer(stub_->Write(&context, &response));
  v1::WriteRequest request;
  rpc::ToProto(digest, request.mutable_digest());
  absl::Status local;
  while (true) {
    absl::StatusOr<std::string> chunk = next();
    if (!chunk.ok()) {
      local = chunk.status();
      break;
    }
    const bool last =
        chunk->empty() || offset + static_cast<int64_t>(chunk->size()) >= digest.size_bytes;
    request.set_write_offset(offset);
    offset += static_cast<int64_t>(chunk->size());
    request.set_data(std::move(*chunk));
    request.set_finish_write(finish && last);
    if (!writer->Write(request)) break;  // the server ended the call: its status says why
    if (progress) progress(offset, digest.size_bytes);
    if (last) break;
    request.clear_digest();
  }
  writer->WritesDone();
  const grpc::Status status = writer->Finish();
  RETURN_IF_ERROR(local);
  RETURN_IF_ERROR(FromGrpcStatus(status));
  return response.committed_size();
}

absl::StatusOr<std::string> RemoteBlobStore::Read(const store::Digest& digest, int64_t offset,
                                                  int64_t limit) {
  v1::ReadRequest request;
  rpc::ToProto(digest, request.mutable_digest());
  request.set_read_offset(offset);
  request.set_read_limit(limit);
  grpc::ClientContext context;
  std::unique_ptr<grpc::ClientReader<v1::ReadResponse>> reader(stub_->Read(&context, request));
  std::string bytes;
  v1::ReadResponse chunk;
  while (reader->Read(&chunk)) bytes += chunk.data();
  RETURN_IF_ERROR(FromGrpcStatus(reader->Finish()));
  return bytes;
}

absl::StatusOr<int64_t> RemoteBlobStore::CommittedSize(const store::Digest& digest) {
  v1::QueryWriteStatusRequest request;
  rpc::ToProto(digest, request.mutable_digest());
  v1::QueryWriteStatusResponse response;
  grpc::ClientContext context;
  RETURN_IF_ERROR(FromGrpcStatus(stub_->QueryWriteStatus(&context, request, &response)));
  return response.committed_size();
}

absl::StatusOr<int64_t> RemoteBlobStore::Append(const store::Digest& digest, int64_t offset,
                                                absl::string_view data) {
  RETURN_IF_ERROR(CheckSize(digest));
  bool sent = false;
  return WriteStream(
      digest, offset,
      [&]() -> absl::StatusOr<std::string> {
        if (sent) return std::string();
        sent = true;
        return std::string(data);
      },
      false, nullptr);
}

absl::Status RemoteBlobStore::FinishUpload(const store::Digest& digest) {
  ASSIGN_OR_RETURN(int64_t committed, CommittedSize(digest));
  return WriteStream(
             digest, committed, []() -> absl::StatusOr<std::string> { return std::string(); }, true,
             nullptr)
      .status();
}

absl::StatusOr<store::StoreStats> RemoteBlobStore::Stats() {
  grpc::ClientContext context;
  v1::GetStoreInfoRequest request;
  request.set_statistics(true);
  v1::GetStoreInfoResponse info;
  RETURN_IF_ERROR(FromGrpcStatus(stub_->GetStoreInfo(&context, request, &info)));
  return store::StoreStats{info.blob_count(), info.total_bytes(), info.partial_uploads(),
                           info.partial_bytes(), info.expired_uploads()};
}

absl::Status RemoteBlobStore::PutFile(const store::Digest& digest, const std::string& path,
                                      const store::TransferProgress& progress) {
  RETURN_IF_ERROR(store::ValidateDigest(digest));
  RETURN_IF_ERROR(CheckSize(digest));
  if (digest.size_bytes <= options_.max_batch_bytes) {
    return BlobStore::PutFile(digest, path, progress);  // one batch call
  }
  v1::QueryWriteStatusRequest request;
  rpc::ToProto(digest, request.mutable_digest());
  v1::QueryWriteStatusResponse status;
  grpc::ClientContext context;
  RETURN_IF_ERROR(FromGrpcStatus(stub_->QueryWriteStatus(&context, request, &status)));
  if (status.complete()) {
    if (progress) progress(digest.size_bytes, digest.size_bytes);
    return absl::OkStatus();
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  int64_t offset = status.committed_size();  // resume where an interrupted upload stopped
  in.seekg(offset);
  return WriteStream(
             digest, offset,
             [&]() -> absl::StatusOr<std::string> {
               const int64_t n = std::min(kChunk, digest.size_bytes - offset);
               std::string chunk(static_cast<size_t>(n), '\0');
               in.read(chunk.data(), n);
               if (in.gcount() != n)
                 return absl::DataLossError(absl::StrCat(path, ": shorter than its digest says"));
               offset += n;
               return chunk;
             },
             true, progress)
      .status();
}

}  // namespace instascene::store_service
