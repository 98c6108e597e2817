// common/rpc/status.h: the one place where absl::Status and grpc::Status meet, and conversions of
// shared proto types. Services return absl::Status from their cores and convert once here.
// Thread-safe: stateless.
#pragma once

#include <grpcpp/support/status.h>

#include "absl/status/status.h"
#include "common/store/digest.h"
#include "instascene/v1/common.pb.h"

namespace instascene::rpc {

// Converts a status for a client: the message passes through ScrubPaths.
grpc::Status ToGrpcStatus(const absl::Status& status);
// Server file system paths never reach clients: every absolute path in `text` (a '/' at the start
// or after white space, a quote, '(' or '=') becomes "<server>/" and its last component, which is
// what a user can act on ("<server>/v003.png: cannot open").
std::string ScrubPaths(absl::string_view text);
absl::Status FromGrpcStatus(const grpc::Status& status);

void ToProto(const store::Digest& digest, v1::Digest* out);
v1::Digest ToProto(const store::Digest& digest);
store::Digest FromProto(const v1::Digest& digest);
// FromProto + ValidateDigest; errors name `field`.
absl::StatusOr<store::Digest> ParseProtoDigest(const v1::Digest& digest, absl::string_view field);

}  // namespace instascene::rpc
