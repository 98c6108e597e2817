#include "services/store/store_service.h"

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/rpc/status.h"

namespace instascene::store_service {

using rpc::ToGrpcStatus;

namespace {
constexpr int64_t kReadChunk = 1 << 20;

void SetBlobStatus(const store::Digest& d, const absl::Status& s, v1::BlobStatus* out) {
  rpc::ToProto(d, out->mutable_digest());
  out->set_code(static_cast<int>(s.code()));
  out->set_message(std::string(s.message()));
}
}  // namespace

grpc::Status StoreService::FindMissingBlobs(grpc::ServerContext*,
                                            const v1::FindMissingBlobsRequest* request,
                                            v1::FindMissingBlobsResponse* response) {
  std::vector<store::Digest> digests;
  for (int i = 0; i < request->digests_size(); ++i) {
    absl::StatusOr<store::Digest> d =
        rpc::ParseProtoDigest(request->digests(i), absl::StrCat("digests[", i, "]"));
    if (!d.ok()) return ToGrpcStatus(d.status());
    digests.push_back(*d);
  }
  absl::StatusOr<std::vector<store::Digest>> missing = store_->FindMissing(digests);
  if (!missing.ok()) return ToGrpcStatus(missing.status());
  for (const store::Digest& d : *missing) rpc::ToProto(d, response->add_missing());
  return grpc::Status::OK;
}

grpc::Status StoreService::BatchUpdateBlobs(grpc::ServerContext*,
                                            const v1::BatchUpdateBlobsRequest* request,
                                            v1::BatchUpdateBlobsResponse* response) {
  int64_t total = 0;
  for (const auto& blob : request->blobs()) total += static_cast<int64_t>(blob.data().size());
  if (total > store_->options().max_batch_bytes)
    return ToGrpcStatus(absl::ResourceExhaustedError(
        absl::StrCat("batch of ", total, " bytes exceeds the limit of ",
                     store_->options().max_batch_bytes, "; stream large blobs with Write")));
  // Each blob stands alone: one bad blob does not reject the others.
  for (int i = 0; i < request->blobs_size(); ++i) {
    const auto& blob = request->blobs(i);
    absl::StatusOr<store::Digest> d =
        rpc::ParseProtoDigest(blob.digest(), absl::StrCat("blobs[", i, "].digest"));
    const absl::Status s = d.ok() ? store_->Put(*d, blob.data()) : d.status();
    SetBlobStatus(rpc::FromProto(blob.digest()), s, response->add_statuses());
  }
  return grpc::Status::OK;
}

grpc::Status StoreService::BatchReadBlobs(grpc::ServerContext*,
                                          const v1::BatchReadBlobsRequest* request,
                                          v1::BatchReadBlobsResponse* response) {
  int64_t total = 0;
  for (int i = 0; i < request->digests_size(); ++i) {
    auto* out = response->add_blobs();
    absl::StatusOr<store::Digest> d =
        rpc::ParseProtoDigest(request->digests(i), absl::StrCat("digests[", i, "]"));
    absl::Status s = d.status();
    if (d.ok()) {
      total += d->size_bytes;
      if (total > store_->options().max_batch_bytes) {
        s = absl::ResourceExhaustedError("batch read over the batch limit; use Read");
      } else {
        absl::StatusOr<std::string> bytes = store_->Read(*d, 0, 0);
        s = bytes.status();
        if (bytes.ok()) *out->mutable_data() = std::move(*bytes);
      }
    }
    SetBlobStatus(rpc::FromProto(request->digests(i)), s, out->mutable_status());
  }
  return grpc::Status::OK;
}

grpc::Status StoreService::Write(grpc::ServerContext*, grpc::ServerReader<v1::WriteRequest>* reader,
                                 v1::WriteResponse* response) {
  v1::WriteRequest request;
  if (!reader->Read(&request))
    return ToGrpcStatus(absl::InvalidArgumentError("Write: empty stream"));
  absl::StatusOr<store::Digest> d = rpc::ParseProtoDigest(request.digest(), "Write.digest");
  if (!d.ok()) return ToGrpcStatus(d.status());
  if (d->size_bytes > store_->options().max_blob_bytes)
    return ToGrpcStatus(absl::ResourceExhaustedError(
        absl::StrCat("blob ", d->ToString(), " is larger than the store's limit of ",
                     store_->options().max_blob_bytes, " bytes")));
  absl::StatusOr<int64_t> committed = store_->CommittedSize(*d);
  if (!committed.ok()) return ToGrpcStatus(committed.status());
  bool finished = false;
  do {
    if (finished) return ToGrpcStatus(absl::InvalidArgumentError("Write: data after finish_write"));
    if (!request.data().empty() || request.write_offset() != *committed) {
      if (*committed == d->size_bytes && request.data().empty()) {
        // Already complete (e.g. resumed after the final chunk landed): nothing to append.
      } else {
        committed = store_->Append(*d, request.write_offset(), request.data());
        if (!committed.ok()) return ToGrpcStatus(committed.status());
      }
    }
    if (request.finish_write()) {
      if (absl::Status s = store_->FinishUpload(*d); !s.ok()) return ToGrpcStatus(s);
      finished = true;
    }
  } while (reader->Read(&request));
  if (!finished && *committed == d->size_bytes) {
    // All bytes arrived but the client did not say finish: publish anyway (verified).
    if (absl::Status s = store_->FinishUpload(*d); !s.ok()) return ToGrpcStatus(s);
  }
  response->set_committed_size(*committed);
  return grpc::Status::OK;
}

grpc::Status StoreService::QueryWriteStatus(grpc::ServerContext*,
                                            const v1::QueryWriteStatusRequest* request,
                                            v1::QueryWriteStatusResponse* response) {
  absl::StatusOr<store::Digest> d = rpc::ParseProtoDigest(request->digest(), "digest");
  if (!d.ok()) return ToGrpcStatus(d.status());
  absl::StatusOr<int64_t> committed = store_->CommittedSize(*d);
  if (!committed.ok()) return ToGrpcStatus(committed.status());
  absl::StatusOr<std::vector<store::Digest>> missing = store_->FindMissing({*d});
  if (!missing.ok()) return ToGrpcStatus(missing.status());
  response->set_committed_size(*committed);
  response->set_complete(missing->empty());
  return grpc::Status::OK;
}

grpc::Status StoreService::Read(grpc::ServerContext* context, const v1::ReadRequest* request,
                                grpc::ServerWriter<v1::ReadResponse>* writer) {
  absl::StatusOr<store::Digest> d = rpc::ParseProtoDigest(request->digest(), "digest");
  if (!d.ok()) return ToGrpcStatus(d.status());
  const int64_t begin = request->read_offset();
  if (begin < 0 || begin > d->size_bytes || request->read_limit() < 0)
    return ToGrpcStatus(absl::OutOfRangeError(
        absl::StrCat("read offset ", begin, " / limit ", request->read_limit(),
                     " out of range for blob ", d->ToString())));
  int64_t end = d->size_bytes;
  if (request->read_limit() > 0) end = std::min(end, begin + request->read_limit());
  int64_t offset = begin;
  do {
    if (context->IsCancelled()) return grpc::Status::CANCELLED;
    const int64_t n = std::min(kReadChunk, end - offset);
    absl::StatusOr<std::string> bytes = store_->Read(*d, offset, n == 0 ? 0 : n);
    if (!bytes.ok()) return ToGrpcStatus(bytes.status());
    if (n == 0) bytes->clear();
    v1::ReadResponse chunk;
    *chunk.mutable_data() = std::move(*bytes);
    if (!writer->Write(chunk)) return grpc::Status::CANCELLED;
    offset += n;
  } while (offset < end);
  return grpc::Status::OK;
}

grpc::Status StoreService::GetStoreInfo(grpc::ServerContext*, const v1::GetStoreInfoRequest*,
                                        v1::GetStoreInfoResponse* response) {
  absl::StatusOr<store::StoreStats> stats = store_->Stats();
  if (!stats.ok()) return ToGrpcStatus(stats.status());
  response->set_max_blob_bytes(store_->options().max_blob_bytes);
  response->set_max_batch_bytes(store_->options().max_batch_bytes);
  response->set_blob_count(stats->blob_count);
  response->set_total_bytes(stats->total_bytes);
  response->set_partial_uploads(stats->partial_uploads);
  response->set_partial_bytes(stats->partial_bytes);
  response->set_expired_uploads(stats->expired_uploads);
  return grpc::Status::OK;
}

}  // namespace instascene::store_service
