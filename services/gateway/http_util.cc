#include "services/gateway/http_util.h"

#include <google/protobuf/util/json_util.h>

#include <chrono>

#include <nlohmann/json.hpp>

#include "absl/status/status.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

namespace instascene::gateway {
namespace {
constexpr auto kDeadline = std::chrono::seconds(60);
}  // namespace

// Google's HTTP mapping of the canonical codes.
int HttpStatus(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK:
      return 200;
    case grpc::StatusCode::CANCELLED:
      return 499;
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::FAILED_PRECONDITION:
    case grpc::StatusCode::OUT_OF_RANGE:
      return 400;
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return 504;
    case grpc::StatusCode::NOT_FOUND:
      return 404;
    case grpc::StatusCode::ALREADY_EXISTS:
    case grpc::StatusCode::ABORTED:
      return 409;
    case grpc::StatusCode::PERMISSION_DENIED:
      return 403;
    case grpc::StatusCode::UNAUTHENTICATED:
      return 401;
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return 429;
    case grpc::StatusCode::UNIMPLEMENTED:
      return 501;
    case grpc::StatusCode::UNAVAILABLE:
      return 503;
    default:
      return 500;
  }
}

std::string StatusName(grpc::StatusCode code) {  // "NOT_FOUND": absl and gRPC share the codes
  return absl::StatusCodeToString(static_cast<absl::StatusCode>(code));
}

// {"error": {"code": HTTP, "status": "NOT_FOUND", "message": "..."}} (nlohmann quotes the message).
std::string ErrorJson(int http_status, grpc::StatusCode code, const std::string& message) {
  return nlohmann::json{
             {"error", {{"code", http_status}, {"status", StatusName(code)}, {"message", message}}}}
             .dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) +
         "\n";
}

// `http_status` 0 = the code's own mapping.
void SendError(httplib::Response& res, const grpc::Status& s, int http_status) {
  res.status = http_status != 0 ? http_status : HttpStatus(s.error_code());
  res.set_content(ErrorJson(res.status, s.error_code(), s.error_message()), "application/json");
}

void SendError(httplib::Response& res, grpc::StatusCode code, const std::string& message) {
  SendError(res, grpc::Status(code, message));
}

std::string ToJson(const google::protobuf::Message& m) {
  google::protobuf::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  std::string out;
  (void)google::protobuf::util::MessageToJsonString(m, &out, options);
  return out;
}

void SendMessage(httplib::Response& res, const google::protobuf::Message& m) {
  res.set_content(ToJson(m) + "\n", "application/json");
}

// A gRPC call context carrying the caller's token and a deadline.
void Prepare(const httplib::Request& req, grpc::ClientContext* context, bool allow_query_token) {
  std::string authorization = req.get_header_value("Authorization");
  if (authorization.empty() && allow_query_token && req.has_param("access_token"))
    authorization = "Bearer " + req.get_param_value("access_token");
  if (!authorization.empty()) context->AddMetadata("authorization", authorization);
  context->set_deadline(std::chrono::system_clock::now() + kDeadline);
}

bool ParseBody(const httplib::Request& req, httplib::Response& res,
               google::protobuf::Message* message) {
  google::protobuf::util::JsonParseOptions options;
  options.ignore_unknown_fields = false;
  const auto status = google::protobuf::util::JsonStringToMessage(req.body, message, options);
  if (!status.ok()) {
    SendError(res, grpc::StatusCode::INVALID_ARGUMENT,
              absl::StrCat("request body: ", std::string(status.message())));
    return false;
  }
  return true;
}

bool ParseDigest(const std::string& hash, const std::string& size, v1::Digest* out,
                 httplib::Response& res) {
  int64_t bytes = 0;
  if (!absl::SimpleAtoi(size, &bytes) || bytes < 0) {
    SendError(res, grpc::StatusCode::INVALID_ARGUMENT, "blob size: not a non-negative integer");
    return false;
  }
  out->set_hash(hash);
  out->set_size_bytes(bytes);
  return true;
}

bool ParseVector(const std::string& text, size_t n, std::vector<double>* out) {
  out->clear();
  for (absl::string_view p : absl::StrSplit(text, ',')) {
    double v = 0;
    if (!absl::SimpleAtod(p, &v)) return false;
    out->push_back(v);
  }
  return out->size() == n;
}

// Content type of an artefact by its file name (what the viewer and robot tools expect).
std::string MediaType(const std::string& name) {
  static const std::pair<const char*, const char*> kTypes[] = {
      {".json", "application/json"}, {".png", "image/png"},        {".jpg", "image/jpeg"},
      {".glb", "model/gltf-binary"}, {".gltf", "model/gltf+json"}, {".stl", "model/stl"},
      {".urdf", "application/xml"},  {".xml", "application/xml"},  {".ply", "application/ply"},
      {".obj", "model/obj"}};
  for (const auto& [ext, type] : kTypes)
    if (absl::EndsWith(name, ext)) return type;
  return "application/octet-stream";
}

}  // namespace instascene::gateway
