#include "common/rpc/status.h"

#include "absl/strings/str_cat.h"

namespace instascene::rpc {

std::string ScrubPaths(absl::string_view text) {
  std::string out;
  out.reserve(text.size());
  auto opens_path = [&](size_t i) {
    if (text[i] != '/' || i + 1 >= text.size() || text[i + 1] == '/' || text[i + 1] == ' ')
      return false;
    if (i == 0) return true;
    const char before = text[i - 1];
    return before == ' ' || before == '\'' || before == '"' || before == '(' || before == '=' ||
           before == '\t' || before == '\n';
  };
  auto ends_path = [](char c) {
    return c == ' ' || c == '\'' || c == '"' || c == ')' || c == ',' || c == ';' || c == ':' ||
           c == '\t' || c == '\n';
  };
  for (size_t i = 0; i < text.size();) {
    if (!opens_path(i)) {
      out.push_back(text[i++]);
      continue;
    }
    size_t end = i;
    while (end < text.size() && !ends_path(text[end])) ++end;
    absl::string_view path = text.substr(i, end - i);
    while (path.size() > 1 && path.back() == '/') path.remove_suffix(1);
    absl::StrAppend(&out, "<server>/", path.substr(path.rfind('/') + 1));
    i = end;
  }
  return out;
}

grpc::Status ToGrpcStatus(const absl::Status& status) {
  if (status.ok()) return grpc::Status::OK;
  // absl and gRPC share the canonical code numbering.
  return grpc::Status(static_cast<grpc::StatusCode>(status.code()), ScrubPaths(status.message()));
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
