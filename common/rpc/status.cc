#include "common/rpc/status.h"

#include "absl/strings/str_cat.h"

namespace instascene::rpc {

grpc::Status ToGrpcStatus(const absl::Status& status) {
  if (status.ok()) return grpc::Status::OK;
  // absl and gRPC share the canonical code numbering.
  return grpc::Status(static_cast<grpc::StatusCode>(status.code()), std::string(status.message()));
}

absl::Status FromGrpcStatus(const grpc::Status& status) {
  if (status.ok()) return absl::OkStatus();
  return absl::Status(static_cast<absl::StatusCode>(status.error_code()), status.error_message());
}

void ToProto(const store::Digest& digest, v1::Digest* out) {
  out->set_hash(digest.hash);
  out->set_size_bytes(digest.size_bytes);
}

v1::Digest ToProto(const store::Digest& digest) {
  v1::Digest d;
  ToProto(digest, &d);
  return d;
}

store::Digest FromProto(const v1::Digest& digest) {
  return store::Digest{digest.hash(), digest.size_bytes()};
}

absl::StatusOr<store::Digest> ParseProtoDigest(const v1::Digest& digest, absl::string_view field) {
  const store::Digest d = FromProto(digest);
  if (absl::Status s = store::ValidateDigest(d); !s.ok())
    return absl::InvalidArgumentError(absl::StrCat(field, ": ", s.message()));
  return d;
}

}  // namespace instascene::rpc
