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

using auth::Role;
constexpr size_t kMaxDigestsPerCall = 10000;

absl::StatusOr<std::vector<store::Digest>> ParseDigests(
    const google::protobuf::RepeatedPtrField<v1::Digest>& in) {
  if (in.size() > static_cast<int>(kMaxDigestsPerCall))
    return absl::InvalidArgumentError(
        absl::StrCat(in.size(), " digests in one call (at most ", kMaxDigestsPerCall, ")"));
  std::vector<store::Digest> digests;
  for (int i = 0; i < in.size(); ++i) {
    ASSIGN_OR_RETURN(store::Digest d,
                     rpc::ParseProtoDigest(in.Get(i), absl::StrCat("digests[", i, "]")));
    digests.push_back(d);
  }
  return digests;
}

// Where a caller's upload goes: a tenant's upload is its own (BlobStore::Tenant*); everyone
// else's is the shared one.
struct UploadSpace {
  store::BlobStore* store;
  std::string tenant;  // "" = shared

  absl::StatusOr<int64_t> CommittedSize(const store::Digest& d) const {
    return tenant.empty() ? store->CommittedSize(d) : store->TenantCommittedSize(tenant, d);
  }
  absl::StatusOr<int64_t> Append(const store::Digest& d, int64_t offset,
                                 absl::string_view data) const {
    return tenant.empty() ? store->Append(d, offset, data)
                          : store->TenantAppend(tenant, d, offset, data);
  }
  absl::Status Finish(const store::Digest& d) const {
    return tenant.empty() ? store->FinishUpload(d) : store->TenantFinishUpload(tenant, d);
  }
};

}  // namespace

absl::StatusOr<auth::Identity> StoreService::Caller(grpc::ServerContext* context) const {
  return auth::Authorize(auth_, context, {Role::kClient, Role::kWorker, Role::kAdmin});
}

absl::Status StoreService::AdmitNew(const auth::Identity& who, const store::Digest& digest) {
  if (!who.scoped()) return absl::OkStatus();
  return quota_.Admit(who.tenant, digest, [&]() -> absl::StatusOr<bool> {
    ASSIGN_OR_RETURN(std::vector<store::Digest> ungranted,
                     store_->FindUngranted(who.tenant, {digest}));
    return ungranted.empty();
  });
}

absl::Status StoreService::CheckReadable(const auth::Identity& who,
                                         const store::Digest& digest) const {
  if (!who.scoped()) return absl::OkStatus();
  ASSIGN_OR_RETURN(std::vector<store::Digest> ungranted,
                   store_->FindUngranted(who.tenant, {digest}));
  if (!ungranted.empty())
    return absl::NotFoundError(absl::StrCat("blob ", digest.ToString(), " is not in the store"));
  return absl::OkStatus();
}

grpc::Status StoreService::FindMissingBlobs(grpc::ServerContext* context,
                                            const v1::FindMissingBlobsRequest* request,
                                            v1::FindMissingBlobsResponse* response) {
  absl::StatusOr<auth::Identity> who = Caller(context);
  if (!who.ok()) return ToGrpcStatus(who.status());
  absl::StatusOr<std::vector<store::Digest>> digests = ParseDigests(request->digests());
  if (!digests.ok()) return ToGrpcStatus(digests.status());
  absl::StatusOr<std::vector<store::Digest>> missing =
      who->scoped() ? store_->FindUngranted(who->tenant, *digests) : store_->FindMissing(*digests);
  if (!missing.ok()) return ToGrpcStatus(missing.status());
  for (const store::Digest& d : *missing) rpc::ToProto(d, response->add_missing());
  return grpc::Status::OK;
}

grpc::Status StoreService::BatchUpdateBlobs(grpc::ServerContext* context,
                                            const v1::BatchUpdateBlobsRequest* request,
                                            v1::BatchUpdateBlobsResponse* response) {
  absl::StatusOr<auth::Identity> who = Caller(context);
  if (!who.ok()) return ToGrpcStatus(who.status());
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
    // Put verifies the bytes even when the store holds the blob: a tenant proves possession.
    absl::Status s = d.ok() ? AdmitNew(*who, *d) : d.status();
    if (s.ok()) s = store_->Put(*d, blob.data());
    if (s.ok() && who->scoped()) s = store_->Grant(who->tenant, {*d});
    SetBlobStatus(rpc::FromProto(blob.digest()), s, response->add_statuses());
  }
  return grpc::Status::OK;
}

grpc::Status StoreService::BatchReadBlobs(grpc::ServerContext* context,
                                          const v1::BatchReadBlobsRequest* request,
                                          v1::BatchReadBlobsResponse* response) {
  absl::StatusOr<auth::Identity> who = Caller(context);
  if (!who.ok()) return ToGrpcStatus(who.status());
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
      } else if (s = CheckReadable(*who, *d); s.ok()) {
        absl::StatusOr<std::string> bytes = store_->Read(*d, 0, 0);
        s = bytes.status();
        if (bytes.ok()) *out->mutable_data() = std::move(*bytes);
      }
    }
    SetBlobStatus(rpc::FromProto(request->digests(i)), s, out->mutable_status());
  }
  return grpc::Status::OK;
}

grpc::Status StoreService::Write(grpc::ServerContext* context,
                                 grpc::ServerReader<v1::WriteRequest>* reader,
                                 v1::WriteResponse* response) {
  absl::StatusOr<auth::Identity> who = Caller(context);
  if (!who.ok()) return ToGrpcStatus(who.status());
  const UploadSpace uploads{store_, who->tenant};
  v1::WriteRequest request;
  if (!reader->Read(&request))
    return ToGrpcStatus(absl::InvalidArgumentError("Write: empty stream"));
  absl::StatusOr<store::Digest> d = rpc::ParseProtoDigest(request.digest(), "Write.digest");
  if (!d.ok()) return ToGrpcStatus(d.status());
  if (d->size_bytes > store_->options().max_blob_bytes)
    return ToGrpcStatus(absl::ResourceExhaustedError(
        absl::StrCat("blob ", d->ToString(), " is larger than the store's limit of ",
                     store_->options().max_blob_bytes, " bytes")));
  absl::StatusOr<int64_t> committed = uploads.CommittedSize(*d);
  if (!committed.ok()) return ToGrpcStatus(committed.status());
  if (*committed < d->size_bytes) {
    if (absl::Status s = AdmitNew(*who, *d); !s.ok()) return ToGrpcStatus(s);
  }
  bool finished = false;
  do {
    if (finished) return ToGrpcStatus(absl::InvalidArgumentError("Write: data after finish_write"));
    if (!request.data().empty() || request.write_offset() != *committed) {
      if (*committed == d->size_bytes && request.write_offset() >= 0 &&
          request.write_offset() + static_cast<int64_t>(request.data().size()) <= d->size_bytes) {
        // Already complete (resumed after the final chunk landed, or a blob the store or the
        // tenant holds already): the stream's chunks within the blob add nothing.
      } else {
        committed = uploads.Append(*d, request.write_offset(), request.data());
        if (!committed.ok()) return ToGrpcStatus(committed.status());
      }
    }
    if (request.finish_write()) {
      if (absl::Status s = uploads.Finish(*d); !s.ok()) return ToGrpcStatus(s);
      finished = true;
    }
  } while (reader->Read(&request));
  if (!finished && *committed == d->size_bytes) {
    // All bytes arrived but the client did not say finish: publish anyway (verified).
    if (absl::Status s = uploads.Finish(*d); !s.ok()) return ToGrpcStatus(s);
  }
  response->set_committed_size(*committed);
  return grpc::Status::OK;
}

grpc::Status StoreService::QueryWriteStatus(grpc::ServerContext* context,
                                            const v1::QueryWriteStatusRequest* request,
                                            v1::QueryWriteStatusResponse* response) {
  absl::StatusOr<auth::Identity> who = Caller(context);
  if (!who.ok()) return ToGrpcStatus(who.status());
  absl::StatusOr<store::Digest> d = rpc::ParseProtoDigest(request->digest(), "digest");
  if (!d.ok()) return ToGrpcStatus(d.status());
  absl::StatusOr<int64_t> committed =
      who->scoped() ? store_->TenantCommittedSize(who->tenant, *d) : store_->CommittedSize(*d);
  if (!committed.ok()) return ToGrpcStatus(committed.status());
  absl::StatusOr<std::vector<store::Digest>> missing =
      who->scoped() ? store_->FindUngranted(who->tenant, {*d}) : store_->FindMissing({*d});
  if (!missing.ok()) return ToGrpcStatus(missing.status());
  response->set_committed_size(*committed);
  response->set_complete(missing->empty());
  return grpc::Status::OK;
}

grpc::Status StoreService::Read(grpc::ServerContext* context, const v1::ReadRequest* request,
                                grpc::ServerWriter<v1::ReadResponse>* writer) {
  absl::StatusOr<auth::Identity> who = Caller(context);
  if (!who.ok()) return ToGrpcStatus(who.status());
  absl::StatusOr<store::Digest> d = rpc::ParseProtoDigest(request->digest(), "digest");
  if (!d.ok()) return ToGrpcStatus(d.status());
  if (absl::Status s = CheckReadable(*who, *d); !s.ok()) return ToGrpcStatus(s);
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

grpc::Status StoreService::GetStoreInfo(grpc::ServerContext* context,
                                        const v1::GetStoreInfoRequest* request,
                                        v1::GetStoreInfoResponse* response) {
  absl::StatusOr<auth::Identity> who = Caller(context);
  if (!who.ok()) return ToGrpcStatus(who.status());
  response->set_max_blob_bytes(store_->options().max_blob_bytes);
  response->set_max_batch_bytes(store_->options().max_batch_bytes);
  // The store's contents are not a tenant's business; counting them walks the store.
  if (who->scoped() || !request->statistics()) return grpc::Status::OK;
  absl::StatusOr<store::StoreStats> stats = store_->Stats();
  if (!stats.ok()) return ToGrpcStatus(stats.status());
  response->set_blob_count(stats->blob_count);
  response->set_total_bytes(stats->total_bytes);
  response->set_partial_uploads(stats->partial_uploads);
  response->set_partial_bytes(stats->partial_bytes);
  response->set_expired_uploads(stats->expired_uploads);
  return grpc::Status::OK;
}

grpc::Status StoreService::GrantBlobs(grpc::ServerContext* context,
                                      const v1::GrantBlobsRequest* request,
                                      v1::GrantBlobsResponse*) {
  absl::StatusOr<auth::Identity> who =
      auth::Authorize(auth_, context, {Role::kWorker, Role::kAdmin});
  if (!who.ok()) return ToGrpcStatus(who.status());
  absl::StatusOr<std::vector<store::Digest>> digests = ParseDigests(request->digests());
  if (!digests.ok()) return ToGrpcStatus(digests.status());
  return ToGrpcStatus(store_->Grant(request->tenant(), *digests));
}

grpc::Status StoreService::FindUngrantedBlobs(grpc::ServerContext* context,
                                              const v1::FindUngrantedBlobsRequest* request,
                                              v1::FindUngrantedBlobsResponse* response) {
  absl::StatusOr<auth::Identity> who =
      auth::Authorize(auth_, context, {Role::kWorker, Role::kAdmin});
  if (!who.ok()) return ToGrpcStatus(who.status());
  absl::StatusOr<std::vector<store::Digest>> digests = ParseDigests(request->digests());
  if (!digests.ok()) return ToGrpcStatus(digests.status());
  absl::StatusOr<std::vector<store::Digest>> ungranted =
      store_->FindUngranted(request->tenant(), *digests);
  if (!ungranted.ok()) return ToGrpcStatus(ungranted.status());
  for (const store::Digest& d : *ungranted) rpc::ToProto(d, response->add_ungranted());
  return grpc::Status::OK;
}

}  // namespace instascene::store_service
