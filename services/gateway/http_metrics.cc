// services/gateway/http_metrics.cc: Prometheus metrics of the gateway's HTTP requests, on the
// process registry (served by `--metrics`): instascene_http_requests_total{route, code} and
// instascene_http_request_duration_seconds{route}. Routes are a fixed set (the API's first path
// segment, "ui" for the bundle, "other"), so no client can grow the label space.
#include <chrono>
#include <set>
#include <string>

#include "absl/strings/match.h"
#include "absl/strings/str_split.h"
#include "common/metrics/metrics.h"
#include "services/gateway/http_util.h"

namespace instascene::gateway {
namespace {

thread_local std::chrono::steady_clock::time_point request_start;

std::string Route(const std::string& path) {
  static const std::set<std::string> kRoutes = {"health", "stages",    "jobs",
                                                "scenes", "pipelines", "queue",
                                                "events", "blobs",     "scene-manifests"};
  if (!absl::StartsWith(path, "/api/")) return "ui";
  std::vector<std::string> parts = absl::StrSplit(path, '/', absl::SkipEmpty());
  if (parts.size() >= 3 && parts[1] == "v1" && kRoutes.count(parts[2])) return parts[2];
  return "other";
}

}  // namespace

void AddHttpMetrics(httplib::Server& http) {
  auto& requests = prometheus::BuildCounter()
                       .Name("instascene_http_requests_total")
                       .Help("HTTP requests the gateway answered, by route and status code")
                       .Register(metrics::Registry());
  auto& durations = prometheus::BuildHistogram()
                        .Name("instascene_http_request_duration_seconds")
                        .Help(
                            "Time from a request's routing to its last byte (event streams: "
                            "their whole life), by route")
                        .Register(metrics::Registry());
  http.set_pre_routing_handler([](const httplib::Request&, httplib::Response&) {
    request_start = std::chrono::steady_clock::now();
    return httplib::Server::HandlerResponse::Unhandled;
  });
  http.set_logger(
      [&requests, &durations](const httplib::Request& req, const httplib::Response& res) {
        const std::string route = Route(req.path);
        requests.Add({{"route", route}, {"code", std::to_string(res.status)}}).Increment();
        const double seconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - request_start).count();
        durations.Add({{"route", route}}, metrics::RpcBuckets()).Observe(seconds);
      });
}

}  // namespace instascene::gateway
