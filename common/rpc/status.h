// common/rpc/status.h: the one place where absl::Status and grpc::Status meet, and conversions of
// shared proto types. Services return absl::Status from their cores and convert once here.
// Thread-safe: stateless.
#pragma once

#include <grpcpp/support/status.h>

#include "absl/status/status.h"
#include "common/store/digest.h"
#include "instascene/v1/common.pb.h"

namespace instascene::rpc {

grpc::Status ToGrpcStatus(const absl::Status& status);
absl::Status FromGrpcStatus(const grpc::Status& status);

void ToProto(const store::Digest& digest, v1::Digest* out);
v1::Digest ToProto(const store::Digest& digest);
store::Digest FromProto(const v1::Digest& digest);
// FromProto + ValidateDigest; errors name `field`.
absl::StatusOr<store::Digest> ParseProtoDigest(const v1::Digest& digest, absl::string_view field);

}  // namespace instascene::rpc
