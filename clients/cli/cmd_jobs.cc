// `instascene watch | jobs`: a running server's jobs, followed live or listed as a table.
#include <cstdio>
#include <map>
#include <optional>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/cli/cli.h"
#include "clients/cli/connection.h"
#include "clients/cli/job_view.h"
#include "common/core/status.h"
#include "instascene/client/services.h"
#include "services/scheduler/job_proto.h"

namespace instascene::cli {

// `watch`: follows jobs live until they finish.
void AddWatchCommand(CLI::App& app, Action* action) {
  struct WatchArgs {
    std::string server = kDefaultServer, scene;
    ConnectionFlags connection;
    std::vector<std::string> ids;
    bool json = false;
  };
  auto watch = std::make_shared<WatchArgs>();
  CLI::App* w = app.add_subcommand(
      "watch",
      "Follow jobs live (state, phase, step, loss, ETA) until they finish; exits 1 if "
      "any failed or was cancelled");
  w->add_option("ids", watch->ids, "Job ids");
  w->add_option("--scene", watch->scene, "Every job of this scene");
  w->add_option("--server", watch->server, "Scheduler address")->capture_default_str();
  AddConnectionFlags(w, &watch->connection);
  w->add_flag("--json", watch->json, "Print the final jobs as one JSON object");
  w->callback([watch, action] {
    *action = [watch]() -> absl::Status {
      if (watch->ids.empty() && watch->scene.empty())
        return absl::InvalidArgumentError("give job ids or --scene");
      ASSIGN_OR_RETURN(std::unique_ptr<client::Client> c,
                       ConnectClient(watch->connection, watch->server));
      ASSIGN_OR_RETURN(auto jobs, WatchJobs(*c, watch->ids, watch->scene));
      nlohmann::json out = nlohmann::json::array();
      std::string bad;
      for (const auto& [id, j] : jobs) {
        out.push_back(JobJson(j));
        if (j.state() != v1::JOB_STATE_SUCCEEDED) bad = id;
      }
      if (watch->json) PrintJsonLine(nlohmann::json({{"jobs", out}}).dump());
      if (!bad.empty())
        return absl::AbortedError(absl::StrCat("job ", bad, " ended ",
                                               scheduler::StateName(jobs[bad].state()), ": ",
                                               jobs[bad].error()));
      return absl::OkStatus();
    };
  });
}

namespace {

struct JobsArgs {
  std::string server = kDefaultServer, scene, state, page_token;
  ConnectionFlags connection;
  int limit = 50;
  bool json = false;
};

absl::StatusOr<v1::ListJobsResponse> ListJobs(const JobsArgs& a, client::Client& c) {
  v1::ListJobsRequest request;
  request.set_scene(a.scene);
  request.set_limit(a.limit);
  request.set_page_token(a.page_token);
  if (!a.state.empty()) {
    for (int st = v1::JOB_STATE_QUEUED; st <= v1::JOB_STATE_CANCELLED; ++st) {
      if (scheduler::StateName(static_cast<v1::JobState>(st)) == a.state)
        request.set_state(static_cast<v1::JobState>(st));
    }
  }
  v1::ListJobsResponse response;
  RETURN_IF_ERROR(client::Call(c, "scheduler", [&](grpc::ClientContext* context) {
    return client::SchedulerStub(c).ListJobs(context, request, &response);
  }));
  return response;
}

// Queue-wide figures are monitoring (admins); a client token lists its own jobs only: nullopt.
absl::StatusOr<std::optional<v1::QueueStats>> QueueStats(client::Client& c) {
  v1::QueueStats stats;
  const absl::Status status = client::Call(c, "scheduler", [&](grpc::ClientContext* context) {
    return client::SchedulerStub(c).GetQueueStats(context, v1::GetQueueStatsRequest(), &stats);
  });
  if (absl::IsPermissionDenied(status)) return std::nullopt;
  RETURN_IF_ERROR(status);
  return stats;
}

// Prints the jobs as a table (with --scene as their DAG: children indented under their first
// input); returns them as JSON.
nlohmann::json PrintJobTable(const v1::ListJobsResponse& response, bool as_tree) {
  std::printf("%-17s %-22s %-16s %-9s %-3s %s\n", "JOB", "KIND", "SCENE", "STATE", "TRY",
              "PROGRESS / ERROR");
  nlohmann::json jobs = nlohmann::json::array();
  std::vector<const v1::Job*> ordered;  // oldest first
  for (auto it = response.jobs().rbegin(); it != response.jobs().rend(); ++it)
    ordered.push_back(&*it);
  std::vector<std::pair<int, const v1::Job*>> rows;
  if (!as_tree) {
    for (auto it = ordered.rbegin(); it != ordered.rend(); ++it) rows.emplace_back(0, *it);
  } else {
    rows = JobTree(ordered);
  }
  for (const auto& [depth, jp] : rows) {
    const v1::Job& j = *jp;
    std::string label = std::string(2 * depth, ' ') + (depth > 0 ? "└ " : "") + KindLabel(j);
    if (j.dependencies_size() > 1) absl::StrAppend(&label, " (", j.dependencies_size(), " in)");
    std::printf("%-17s %-22s %-16s %-9s %d/%d %s\n", j.id().c_str(), label.c_str(),
                j.scene().substr(0, 16).c_str(), scheduler::StateName(j.state()).c_str(),
                j.attempts(), j.max_attempts(),
                j.error().empty() ? ProgressText(j).c_str() : j.error().c_str());
    jobs.push_back(JobJson(j));
  }
  return jobs;
}

// Prints the queue's counts by state; returns the statistics as JSON.
nlohmann::json PrintQueueStats(const v1::QueueStats& stats) {
  nlohmann::json by_state = nlohmann::json::object();
  std::string line;
  for (const char* state : {"queued", "leased", "running", "succeeded", "failed", "cancelled"}) {
    auto it = stats.jobs_by_state().find(state);
    const int64_t n = it == stats.jobs_by_state().end() ? 0 : it->second;
    by_state[state] = n;
    absl::StrAppend(&line, state, " ", n, "  ");
  }
  std::printf("queue: %s| scenes %lld | oldest queued %.1f s\n", line.c_str(),
              static_cast<long long>(stats.scenes()), stats.oldest_queued_age_ms() / 1000.0);
  return {{"jobs_by_state", by_state},
          {"scenes", stats.scenes()},
          {"oldest_queued_age_ms", stats.oldest_queued_age_ms()}};
}

absl::Status RunJobs(const JobsArgs& a) {
  ASSIGN_OR_RETURN(std::unique_ptr<client::Client> c, ConnectClient(a.connection, a.server));
  ASSIGN_OR_RETURN(const v1::ListJobsResponse response, ListJobs(a, *c));
  ASSIGN_OR_RETURN(const std::optional<v1::QueueStats> stats, QueueStats(*c));
  const nlohmann::json jobs = PrintJobTable(response, !a.scene.empty());
  const nlohmann::json stats_json = stats ? PrintQueueStats(*stats) : nlohmann::json(nullptr);
  if (!response.next_page_token().empty())
    std::printf("more: --page-token %s\n", response.next_page_token().c_str());
  if (a.json)
    PrintJsonLine(nlohmann::json({{"jobs", jobs},
                                  {"next_page_token", response.next_page_token()},
                                  {"stats", stats_json}})
                      .dump());
  return absl::OkStatus();
}

}  // namespace

// `jobs`: the job queue as a table, with queue statistics.
void AddJobsCommand(CLI::App& app, Action* action) {
  auto list = std::make_shared<JobsArgs>();
  CLI::App* l = app.add_subcommand("jobs", "The job queue as a table, with queue statistics");
  l->add_option("--server", list->server, "Scheduler address")->capture_default_str();
  AddConnectionFlags(l, &list->connection);
  l->add_option("--scene", list->scene, "Only this scene");
  l->add_option("--state", list->state, "Only this state")
      ->check(CLI::IsMember({"queued", "leased", "running", "succeeded", "failed", "cancelled"}));
  l->add_option("--limit", list->limit, "At most this many (newest first; at most 1000)");
  l->add_option("--page-token", list->page_token,
                "Continue after the previous page (its next_page_token)");
  l->add_flag("--json", list->json, "Print {\"jobs\", \"stats\"} as the last stdout line");
  l->callback([list, action] { *action = [list] { return RunJobs(*list); }; });
}

}  // namespace instascene::cli
