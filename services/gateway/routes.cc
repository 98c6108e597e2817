#include "services/gateway/routes.h"

#include <google/protobuf/util/json_util.h>

#include <algorithm>

#include <nlohmann/json.hpp>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "common/rpc/status.h"
#include "instascene/v1/objects.grpc.pb.h"
#include "instascene/v1/scheduler.grpc.pb.h"
#include "instascene/v1/store.grpc.pb.h"

namespace instascene::gateway {
namespace {

constexpr int64_t kDownloadChunk = 1 << 20;

// The job listing's query (scene, page_token, limit, state); false after answering a bad one.
bool ParseListJobs(const httplib::Request& req, httplib::Response& res,
                   v1::ListJobsRequest* request) {
  request->set_scene(req.get_param_value("scene"));
  request->set_page_token(req.get_param_value("page_token"));
  if (req.has_param("limit")) {
    int limit = 0;
    if (!absl::SimpleAtoi(req.get_param_value("limit"), &limit)) {
      SendError(res, grpc::StatusCode::INVALID_ARGUMENT, "limit: not an integer");
      return false;
    }
    request->set_limit(limit);
  }
  if (req.has_param("state")) {
    v1::JobState state;
    if (!v1::JobState_Parse("JOB_STATE_" + absl::AsciiStrToUpper(req.get_param_value("state")),
                            &state)) {
      SendError(res, grpc::StatusCode::INVALID_ARGUMENT,
                "state: queued, leased, running, succeeded, failed or cancelled");
      return false;
    }
    request->set_state(state);
  }
  return true;
}

// Live job events as Server-Sent Events: one "job" event per change, "end" when all are final.
void AddJobEventsRoute(httplib::Server& http, const std::shared_ptr<Stubs>& stubs) {
  http.Get("/api/v1/events", [stubs](const httplib::Request& req, httplib::Response& res) {
    auto request = std::make_shared<v1::WatchJobsRequest>();
    request->set_scene(req.get_param_value("scene"));
    for (absl::string_view id :
         absl::StrSplit(req.get_param_value("job_ids"), ',', absl::SkipEmpty()))
      request->add_job_ids(std::string(id));
    auto context = std::make_shared<grpc::ClientContext>();
    Prepare(req, context.get(), /*allow_query_token=*/true);
    context->set_deadline(std::chrono::system_clock::time_point::max());
    auto reader = std::shared_ptr<grpc::ClientReader<v1::Job>>(
        stubs->scheduler->WatchJobs(context.get(), *request));
    // The first event decides the status: an error before any event is an HTTP error.
    auto first = std::make_shared<v1::Job>();
    if (!reader->Read(first.get())) return SendError(res, reader->Finish());
    res.set_header("Cache-Control", "no-cache");
    res.set_chunked_content_provider("text/event-stream", [stubs, context, reader, first](
                                                              size_t, httplib::DataSink& sink) {
      auto send = [&](const std::string& event, const std::string& data) {
        const std::string frame = absl::StrCat("event: ", event, "\ndata: ", data, "\n\n");
        return sink.write(frame.data(), frame.size());
      };
      bool open = send("job", ToJson(*first));
      v1::Job job;
      while (open && reader->Read(&job)) open = send("job", ToJson(job));
      if (!open) {  // the browser went away: end the watch
        context->TryCancel();
        (void)reader->Finish();
        return false;
      }
      const grpc::Status s = reader->Finish();
      send(s.ok() ? "end" : "error",
           nlohmann::json{{"status", StatusName(s.error_code())}, {"message", s.error_message()}}
               .dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
      sink.done();
      return true;
    });
  });
}

// The stages, the job listing, one job and its cancellation: the Scheduler service.
void AddJobRoutes(httplib::Server& http, const std::shared_ptr<Stubs>& stubs) {
  http.Get("/api/v1/stages", [stubs](const httplib::Request& req, httplib::Response& res) {
    Unary<v1::ListStagesRequest, v1::ListStagesResponse>(
        req, res, v1::ListStagesRequest(),
        [&](auto* c, const auto& q, auto* r) { return stubs->scheduler->ListStages(c, q, r); });
  });
  http.Get("/api/v1/jobs", [stubs](const httplib::Request& req, httplib::Response& res) {
    v1::ListJobsRequest request;
    if (!ParseListJobs(req, res, &request)) return;
    Unary<v1::ListJobsRequest, v1::ListJobsResponse>(
        req, res, request,
        [&](auto* c, const auto& q, auto* r) { return stubs->scheduler->ListJobs(c, q, r); });
  });
  http.Get(R"(/api/v1/jobs/([A-Za-z0-9_-]+))", [stubs](const httplib::Request& req,
                                                       httplib::Response& res) {
    v1::GetJobRequest request;
    request.set_job_id(req.matches[1]);
    Unary<v1::GetJobRequest, v1::Job>(req, res, request, [&](auto* c, const auto& q, auto* r) {
      return stubs->scheduler->GetJob(c, q, r);
    });
  });
  http.Post(R"(/api/v1/jobs/([A-Za-z0-9_-]+)/cancel)", [stubs](const httplib::Request& req,
                                                               httplib::Response& res) {
    v1::CancelJobRequest request;
    request.set_job_id(req.matches[1]);
    Unary<v1::CancelJobRequest, v1::Job>(req, res, request, [&](auto* c, const auto& q, auto* r) {
      return stubs->scheduler->CancelJob(c, q, r);
    });
  });
}

// A scene, its cancellation and deletion, pipeline submission, the queue's statistics: the
// Scheduler service.
void AddSceneRoutes(httplib::Server& http, const std::shared_ptr<Stubs>& stubs) {
  http.Get(R"(/api/v1/scenes/([^/]+))", [stubs](const httplib::Request& req,
                                                httplib::Response& res) {
    v1::GetSceneRequest request;
    request.set_scene(req.matches[1]);
    Unary<v1::GetSceneRequest, v1::Scene>(req, res, request, [&](auto* c, const auto& q, auto* r) {
      return stubs->scheduler->GetScene(c, q, r);
    });
  });
  http.Post(R"(/api/v1/scenes/([^/]+)/cancel)",
            [stubs](const httplib::Request& req, httplib::Response& res) {
              v1::CancelSceneRequest request;
              request.set_scene(req.matches[1]);
              Unary<v1::CancelSceneRequest, v1::CancelSceneResponse>(
                  req, res, request, [&](auto* c, const auto& q, auto* r) {
                    return stubs->scheduler->CancelScene(c, q, r);
                  });
            });
  http.Delete(R"(/api/v1/scenes/([^/]+))",
              [stubs](const httplib::Request& req, httplib::Response& res) {
                v1::DeleteSceneRequest request;
                request.set_scene(req.matches[1]);
                Unary<v1::DeleteSceneRequest, v1::DeleteSceneResponse>(
                    req, res, request, [&](auto* c, const auto& q, auto* r) {
                      return stubs->scheduler->DeleteScene(c, q, r);
                    });
              });
  http.Post("/api/v1/pipelines", [stubs](const httplib::Request& req, httplib::Response& res) {
    v1::SubmitPipelineRequest request;
    if (!ParseBody(req, res, &request)) return;
    Unary<v1::SubmitPipelineRequest, v1::SubmitPipelineResponse>(
        req, res, request,
        [&](auto* c, const auto& q, auto* r) { return stubs->scheduler->SubmitPipeline(c, q, r); });
  });
  http.Get("/api/v1/queue", [stubs](const httplib::Request& req, httplib::Response& res) {
    Unary<v1::GetQueueStatsRequest, v1::QueueStats>(
        req, res, v1::GetQueueStatsRequest(),
        [&](auto* c, const auto& q, auto* r) { return stubs->scheduler->GetQueueStats(c, q, r); });
  });
}

// Jobs, scenes, pipelines, the queue and its live events: the Scheduler service.
void AddSchedulerRoutes(httplib::Server& http, const std::shared_ptr<Stubs>& stubs) {
  AddJobRoutes(http, stubs);
  AddSceneRoutes(http, stubs);
  AddJobEventsRoute(http, stubs);
}

// Resumable upload: each PUT appends its body at Upload-Offset (the committed size, from
// .../status); the chunk that reaches the size finishes the blob (verified by the store).
void UploadChunk(const std::shared_ptr<Stubs>& stubs, const httplib::Request& req,
                 httplib::Response& res) {
  v1::WriteRequest chunk;
  if (!ParseDigest(req.matches[1], req.matches[2], chunk.mutable_digest(), res)) return;
  int64_t offset = 0;
  const std::string offset_header =
      req.has_header("Upload-Offset") ? req.get_header_value("Upload-Offset") : "0";
  if (!absl::SimpleAtoi(offset_header, &offset) || offset < 0)
    return SendError(res, grpc::StatusCode::INVALID_ARGUMENT,
                     "Upload-Offset: not a non-negative integer");
  chunk.set_write_offset(offset);
  chunk.set_data(req.body);
  chunk.set_finish_write(offset + static_cast<int64_t>(req.body.size()) ==
                         chunk.digest().size_bytes());
  grpc::ClientContext context;
  Prepare(req, &context);
  v1::WriteResponse response;
  auto writer = stubs->store->Write(&context, &response);
  writer->Write(chunk);
  writer->WritesDone();
  const grpc::Status s = writer->Finish();
  if (!s.ok()) return SendError(res, s);
  SendMessage(res, response);
}

// Downloads: the blob's bytes, with Range requests (one range) and the content type of `name`.
void DownloadBlob(const std::shared_ptr<Stubs>& stubs, const httplib::Request& req,
                  httplib::Response& res) {
  v1::Digest digest;
  if (!ParseDigest(req.matches[1], req.matches[2], &digest, res)) return;
  {  // exists and readable by this caller (an empty read answers NOT_FOUND / UNAUTHENTICATED)
    grpc::ClientContext context;
    Prepare(req, &context);
    v1::ReadRequest read;
    *read.mutable_digest() = digest;
    read.set_read_limit(1);
    auto reader = stubs->store->Read(&context, read);
    v1::ReadResponse ignored;
    while (reader->Read(&ignored)) {
    }
    if (const grpc::Status s = reader->Finish(); !s.ok()) return SendError(res, s);
  }
  const std::string name = req.get_param_value("name");
  if (!name.empty())
    res.set_header(
        "Content-Disposition",
        absl::StrCat("attachment; filename=\"", name.substr(name.find_last_of('/') + 1), "\""));
  res.set_header("Cache-Control", "private, max-age=31536000, immutable");  // content-addressed
  const std::string authorization = req.get_header_value("Authorization");
  res.set_content_provider(
      static_cast<size_t>(digest.size_bytes()), MediaType(name),
      [stubs, digest, authorization](size_t offset, size_t length, httplib::DataSink& sink) {
        grpc::ClientContext context;
        if (!authorization.empty()) context.AddMetadata("authorization", authorization);
        v1::ReadRequest read;
        *read.mutable_digest() = digest;
        read.set_read_offset(static_cast<int64_t>(offset));
        read.set_read_limit(std::min<int64_t>(static_cast<int64_t>(length), kDownloadChunk));
        auto reader = stubs->store->Read(&context, read);
        v1::ReadResponse chunk;
        while (reader->Read(&chunk))
          if (!sink.write(chunk.data().data(), chunk.data().size())) context.TryCancel();
        return reader->Finish().ok();
      });
}

// Blobs: which are missing, resumable uploads, ranged downloads: the Store service.
void AddStoreRoutes(httplib::Server& http, const std::shared_ptr<Stubs>& stubs) {
  http.Post("/api/v1/blobs/missing", [stubs](const httplib::Request& req, httplib::Response& res) {
    v1::FindMissingBlobsRequest request;
    if (!ParseBody(req, res, &request)) return;
    Unary<v1::FindMissingBlobsRequest, v1::FindMissingBlobsResponse>(
        req, res, request,
        [&](auto* c, const auto& q, auto* r) { return stubs->store->FindMissingBlobs(c, q, r); });
  });
  http.Get(R"(/api/v1/blobs/([0-9a-f]{64})/([0-9]+)/status)",
           [stubs](const httplib::Request& req, httplib::Response& res) {
             v1::QueryWriteStatusRequest request;
             if (!ParseDigest(req.matches[1], req.matches[2], request.mutable_digest(), res))
               return;
             Unary<v1::QueryWriteStatusRequest, v1::QueryWriteStatusResponse>(
                 req, res, request, [&](auto* c, const auto& q, auto* r) {
                   return stubs->store->QueryWriteStatus(c, q, r);
                 });
           });
  http.Put(R"(/api/v1/blobs/([0-9a-f]{64})/([0-9]+))",
           [stubs](const httplib::Request& req, httplib::Response& res) {
             UploadChunk(stubs, req, res);
           });
  http.Get(R"(/api/v1/blobs/([0-9a-f]{64})/([0-9]+))",
           [stubs](const httplib::Request& req, httplib::Response& res) {
             DownloadBlob(stubs, req, res);
           });
}

// An object selector from the query: the id in the path, point=X,Y,Z[&max_distance=D],
// view=V&x=X&y=Y (a click) or ray=OX,OY,OZ,DX,DY,DZ; what is wrong with it, or "".
std::string ParseSelector(const httplib::Request& req, v1::ObjectSelector* selector) {
  std::vector<double> v;
  if (req.matches.size() > 2) {
    uint32_t id = 0;
    if (!absl::SimpleAtoi(std::string(req.matches[2]), &id)) return "object id: not an integer";
    selector->set_id(id);
  } else if (req.has_param("point")) {
    if (!ParseVector(req.get_param_value("point"), 3, &v)) return "point: X,Y,Z";
    selector->mutable_point()->set_x(v[0]);
    selector->mutable_point()->set_y(v[1]);
    selector->mutable_point()->set_z(v[2]);
    double d = 0;
    if (req.has_param("max_distance") && !absl::SimpleAtod(req.get_param_value("max_distance"), &d))
      return "max_distance: not a number";
    selector->set_max_distance(d);
  } else if (req.has_param("view")) {
    int x = 0, y = 0;
    if (!absl::SimpleAtoi(req.get_param_value("x"), &x) ||
        !absl::SimpleAtoi(req.get_param_value("y"), &y))
      return "a click needs integer x and y";
    selector->mutable_click()->set_view(req.get_param_value("view"));
    selector->mutable_click()->set_x(x);
    selector->mutable_click()->set_y(y);
  } else if (req.has_param("ray")) {
    if (!ParseVector(req.get_param_value("ray"), 6, &v)) return "ray: OX,OY,OZ,DX,DY,DZ";
    auto* ray = selector->mutable_ray();
    ray->mutable_origin()->set_x(v[0]);
    ray->mutable_origin()->set_y(v[1]);
    ray->mutable_origin()->set_z(v[2]);
    ray->mutable_direction()->set_x(v[3]);
    ray->mutable_direction()->set_y(v[4]);
    ray->mutable_direction()->set_z(v[5]);
  } else {
    return "give point=X,Y,Z, view=V&x=X&y=Y or ray=OX,OY,OZ,DX,DY,DZ";
  }
  return "";
}

// A scene's objects, and one object by id, point, click or ray: the Objects service.
void AddObjectRoutes(httplib::Server& http, const std::shared_ptr<Stubs>& stubs) {
  http.Get(R"(/api/v1/scenes/([^/]+)/objects)",
           [stubs](const httplib::Request& req, httplib::Response& res) {
             v1::ListObjectsRequest request;
             request.set_scene(req.matches[1]);
             request.set_page_token(req.get_param_value("page_token"));
             if (req.has_param("limit")) {
               int limit = 0;
               if (!absl::SimpleAtoi(req.get_param_value("limit"), &limit))
                 return SendError(res, grpc::StatusCode::INVALID_ARGUMENT, "limit: not an integer");
               request.set_limit(limit);
             }
             Unary<v1::ListObjectsRequest, v1::ListObjectsResponse>(
                 req, res, request, [&](auto* c, const auto& q, auto* r) {
                   return stubs->objects->ListObjects(c, q, r);
                 });
           });
  // One object: by id (/objects/ID), or /object?point=X,Y,Z[&max_distance=D] |
  // ?view=V&x=X&y=Y | ?ray=OX,OY,OZ,DX,DY,DZ.
  auto get_object = [stubs](const httplib::Request& req, httplib::Response& res) {
    v1::GetObjectRequest request;
    request.set_scene(req.matches[1]);
    if (const std::string error = ParseSelector(req, request.mutable_selector()); !error.empty())
      return SendError(res, grpc::StatusCode::INVALID_ARGUMENT, error);
    Unary<v1::GetObjectRequest, v1::Object>(
        req, res, request,
        [&](auto* c, const auto& q, auto* r) { return stubs->objects->GetObject(c, q, r); });
  };
  http.Get(R"(/api/v1/scenes/([^/]+)/objects/([0-9]+))", get_object);
  http.Get(R"(/api/v1/scenes/([^/]+)/object)", get_object);
}

}  // namespace

void AddRoutes(httplib::Server& http, const std::shared_ptr<Stubs>& stubs) {
  http.Get("/api/v1/health", [](const httplib::Request&, httplib::Response& res) {
    res.set_content("{\"status\": \"SERVING\"}\n", "application/json");
  });
  AddSchedulerRoutes(http, stubs);
  AddStoreRoutes(http, stubs);
  AddObjectRoutes(http, stubs);
}

}  // namespace instascene::gateway
