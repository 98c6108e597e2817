// services/gateway/http_util.h: what every gateway route shares: the caller's token and a deadline
// on the gRPC call, JSON bodies through protobuf's JSON mapping, the error model (the gRPC status
// as
// {"error": {"code", "status", "message"}} with Google's HTTP mapping), content types by file name.
// Thread-safe: stateless functions; Stubs are gRPC stubs (thread-safe).
#pragma once

#include <google/protobuf/message.h>
#include <grpcpp/grpcpp.h>
#include <httplib.h>

#include <memory>
#include <string>
#include <vector>

#include "instascene/v1/objects.grpc.pb.h"
#include "instascene/v1/scheduler.grpc.pb.h"
#include "instascene/v1/store.grpc.pb.h"

namespace instascene::gateway {

struct Stubs {
  std::unique_ptr<v1::Scheduler::Stub> scheduler;
  std::unique_ptr<v1::ContentStore::Stub> store;
  std::unique_ptr<v1::Objects::Stub> objects;
};

int HttpStatus(grpc::StatusCode code);          // Google's HTTP mapping of the canonical codes
std::string StatusName(grpc::StatusCode code);  // "NOT_FOUND"
// {"error": {"code": HTTP, "status": "NOT_FOUND", "message": "..."}}
std::string ErrorJson(int http_status, grpc::StatusCode code, const std::string& message);
// `http_status` 0 = the code's own mapping.
void SendError(httplib::Response& res, const grpc::Status& s, int http_status = 0);
void SendError(httplib::Response& res, grpc::StatusCode code, const std::string& message);
std::string ToJson(const google::protobuf::Message& m);  // proto field names, defaults printed
void SendMessage(httplib::Response& res, const google::protobuf::Message& m);
// A gRPC call context carrying the caller's token ("Authorization", or `access_token=` where
// allowed: EventSource cannot set headers) and the gateway's deadline.
void Prepare(const httplib::Request& req, grpc::ClientContext* context,
             bool allow_query_token = false);
// The body as `message` (unknown fields refused); false = an error was sent.
bool ParseBody(const httplib::Request& req, httplib::Response& res,
               google::protobuf::Message* message);
bool ParseDigest(const std::string& hash, const std::string& size, v1::Digest* out,
                 httplib::Response& res);
bool ParseVector(const std::string& text, size_t n, std::vector<double>* out);  // "x,y,z"
std::string MediaType(const std::string& name);  // by extension; octet-stream otherwise

// Unary call helper: stub method called with the caller's token, the answer sent as JSON.
template <typename Request, typename Response, typename Call>
void Unary(const httplib::Request& req, httplib::Response& res, const Request& request, Call call) {
  grpc::ClientContext context;
  Prepare(req, &context);
  Response response;
  const grpc::Status s = call(&context, request, &response);
  if (!s.ok()) return SendError(res, s);
  SendMessage(res, response);
}

// Routes of the scene-folder upload (scene_upload.cc).
void AddSceneUploadRoutes(httplib::Server& http, std::shared_ptr<Stubs> stubs);
// Request counts and durations per route on the process's metrics registry (http_metrics.cc).
void AddHttpMetrics(httplib::Server& http);

}  // namespace instascene::gateway
