// `instascene submit | watch | jobs | fetch | cancel`: clients of a running server.
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <set>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/cli/cli.h"
#include "clients/cli/connection.h"
#include "clients/cli/progress.h"
#include "common/core/status.h"
#include "common/rpc/status.h"
#include "common/scene/image_io.h"
#include "common/scene/scene.h"
#include "instascene/client/services.h"
#include "services/scheduler/job_proto.h"

namespace instascene::cli {
namespace {

constexpr char kDefaultServer[] = "127.0.0.1:50051";

// Every command connects through the C++ client library (deadlines, retries while UNAVAILABLE).
absl::StatusOr<std::unique_ptr<client::Client>> ConnectTo(const ConnectionFlags& connection,
                                                          const std::string& server,
                                                          const std::string& store = "") {
  ASSIGN_OR_RETURN(client::ClientOptions options, ClientOptionsFor(connection, server, store));
  return client::Client::Connect(options);
}

nlohmann::json JobJson(const v1::Job& j) {
  nlohmann::json out = {{"id", j.id()},
                        {"kind", j.kind()},
                        {"scene", j.scene()},
                        {"state", scheduler::StateName(j.state())},
                        {"attempts", j.attempts()},
                        {"worker", j.worker_id()},
                        {"item", j.item()},
                        {"parent", j.parent()},
                        {"error", j.error()},
                        {"phase", j.progress().phase()},
                        {"step", j.progress().step()},
                        {"total", j.progress().total()}};
  nlohmann::json deps = nlohmann::json::object();
  for (const v1::JobDependency& d : j.dependencies()) deps[d.name()] = d.job_id();
  out["dependencies"] = deps;
  if (j.items() >= 0) out["items"] = j.items();
  if (j.has_output_manifest())
    out["output_manifest"] = rpc::FromProto(j.output_manifest()).ToString();
  return out;
}

// A job's label in tables: its kind, with the item index for per-item jobs.
std::string KindLabel(const v1::Job& j) {
  return j.item() >= 0 ? absl::StrCat(j.kind(), "[", j.item(), "]") : j.kind();
}

// The jobs of one scene as a tree: each job under its first dependency (fan-in jobs list the
// others), depth-first in submission order. Returns (depth, job) rows.
std::vector<std::pair<int, const v1::Job*>> JobTree(const std::vector<const v1::Job*>& jobs) {
  std::map<std::string, std::vector<const v1::Job*>> children;
  std::vector<const v1::Job*> roots;
  std::set<std::string> ids;
  for (const v1::Job* j : jobs) ids.insert(j->id());
  for (const v1::Job* j : jobs) {
    if (j->dependencies().empty() || !ids.count(j->dependencies(0).job_id()))
      roots.push_back(j);
    else
      children[j->dependencies(0).job_id()].push_back(j);
  }
  std::vector<std::pair<int, const v1::Job*>> rows;
  std::function<void(const v1::Job*, int)> visit = [&](const v1::Job* j, int depth) {
    rows.emplace_back(depth, j);
    for (const v1::Job* c : children[j->id()]) visit(c, depth + 1);
  };
  for (const v1::Job* r : roots) visit(r, 0);
  return rows;
}

bool IsFinalState(v1::JobState s);

// Live progress of a held job ("" once the job is final: the last report is no longer news).
std::string ProgressText(const v1::Job& j) {
  const v1::Progress& p = j.progress();
  if (p.phase().empty() || IsFinalState(j.state())) return "";
  std::string text =
      p.total() > 0 ? absl::StrFormat("%s %d/%d", p.phase(), p.step(), p.total()) : p.phase();
  if (p.loss() != 0) absl::StrAppendFormat(&text, " loss %.4g", p.loss());
  if (p.eta_seconds() >= 0) absl::StrAppendFormat(&text, " eta %.0fs", p.eta_seconds());
  return text;
}

bool IsFinalState(v1::JobState s) {
  return s == v1::JOB_STATE_SUCCEEDED || s == v1::JOB_STATE_FAILED || s == v1::JOB_STATE_CANCELLED;
}

// Streams job snapshots until every watched job is final. Prints a line per state change and per
// progress step of 10 %; returns the final snapshots.
absl::StatusOr<std::map<std::string, v1::Job>> Watch(client::Client& c,
                                                     const std::vector<std::string>& ids,
                                                     const std::string& scene) {
  v1::WatchJobsRequest request;
  for (const std::string& id : ids) request.add_job_ids(id);
  request.set_scene(scene);
  grpc::ClientContext context;
  std::unique_ptr<grpc::ClientReader<v1::Job>> reader(
      client::SchedulerStub(c).WatchJobs(&context, request));
  std::map<std::string, v1::Job> last;
  std::map<std::string, std::string> printed;
  v1::Job job;
  Stopwatch watch;
  while (reader->Read(&job)) {
    const v1::Progress& p = job.progress();
    const int decile = p.total() > 0 ? static_cast<int>(10 * p.step() / p.total()) : 0;
    const std::string key =
        absl::StrCat(job.state(), "/", p.phase(), "/", decile, "/", job.attempts());
    if (printed[job.id()] != key) {
      printed[job.id()] = key;
      std::fprintf(stderr, "[%6.1fs] %s %-9s %-9s %s%s\n", watch.ElapsedSeconds(), job.id().c_str(),
                   job.kind().c_str(), scheduler::StateName(job.state()).c_str(),
                   ProgressText(job).c_str(),
                   job.error().empty() ? "" : absl::StrCat("  (", job.error(), ")").c_str());
    }
    last[job.id()] = job;
  }
  RETURN_IF_ERROR(client::StatusOf(c, "scheduler", reader->Finish()));
  return last;
}

// `submit`: uploads a scene and submits its pipeline.
void AddSubmitCommand(CLI::App& app, Action* action) {
  struct SubmitArgs {
    std::string server = kDefaultServer, store, scene, name, params;
    ConnectionFlags connection;
    std::vector<std::string> stages;
    int priority = 0, iterations = 0;
    bool iterations_given = false;
    bool json = false, wait = false;
  };
  auto submit = std::make_shared<SubmitArgs>();
  CLI::App* s =
      app.add_subcommand("submit",
                         "Upload a scene (only the blobs the store lacks) and submit its pipeline "
                         "decompose -> train -> segment -> complete (one job per object); prints "
                         "the job ids");
  s->add_option("--scene", submit->scene, "Scene directory")->required();
  s->add_option("--server", submit->server, "Scheduler address")->capture_default_str();
  AddConnectionFlags(s, &submit->connection);
  s->add_option("--store", submit->store, "Store address (default: --server)");
  s->add_option("--name", submit->name, "Scene name shown in job lists (default: directory name)");
  s->add_option("--params", submit->params,
                R"(Stage parameters as JSON, e.g. '{"train":{"iterations":500}}')");
  CLI::Option* iterations =
      s->add_option("--iterations", submit->iterations,
                    "Shortcut for train.iterations (validated by the server like any parameter)");
  s->add_option("--stages", submit->stages,
                "Only these stages, comma-separated (their inputs included), e.g. "
                "decompose,train,segment; default: every stage, export included")
      ->delimiter(',');
  s->add_option("--priority", submit->priority, "Higher runs first (interactive requests)");
  s->add_flag("--wait", submit->wait, "Watch the jobs until they finish");
  s->add_flag("--json", submit->json, "Print {\"scene\", \"jobs\", ...} as the last stdout line");
  s->callback([submit, action, iterations] {
    submit->iterations_given = iterations->count() > 0;
    *action = [submit]() -> absl::Status {
      const SubmitArgs& a = *submit;
      nlohmann::json params = nlohmann::json::object();
      if (!a.params.empty()) {
        params = nlohmann::json::parse(a.params, nullptr, false);
        if (params.is_discarded() || !params.is_object())
          return absl::InvalidArgumentError("--params is not a JSON object");
      }
      if (a.iterations_given) params["train"]["iterations"] = a.iterations;
      {  // every image and mask against its camera (headers only) before anything is sent
        ASSIGN_OR_RETURN(Scene scene, ReadScene(a.scene));
        RETURN_IF_ERROR(CheckViewFiles(scene));
      }
      ASSIGN_OR_RETURN(std::unique_ptr<client::Client> c,
                       ConnectTo(a.connection, a.server, a.store));
      client::SubmitRequest request;
      request.scene_dir = a.scene;
      request.name = a.name;
      request.parameters_json = params.dump();
      request.stages = a.stages;
      request.priority = a.priority;
      ProgressBar bar("upload");
      int64_t last_mb = -1;
      ASSIGN_OR_RETURN(client::SubmitResult submitted,
                       c->Submit(request, [&](int64_t done, int64_t total) {
                         if (done / (1 << 20) == last_mb && done != total) return;
                         last_mb = done / (1 << 20);
                         bar.Update(static_cast<int>(done >> 10), static_cast<int>(total >> 10));
                       }));
      std::fprintf(stderr, "upload: %lld files (%.1f MB) sent, %lld already in the store\n",
                   static_cast<long long>(submitted.files_sent), submitted.bytes_sent / 1e6,
                   static_cast<long long>(submitted.files_skipped));
      nlohmann::json jobs = nlohmann::json::array();
      std::vector<std::string> ids;
      for (const client::SubmittedJob& j : submitted.jobs) {
        std::fprintf(stderr, "job %s %-9s %s%s\n", j.id.c_str(), j.kind.c_str(), j.state.c_str(),
                     j.created ? "" : " (existing job)");
        jobs.push_back({{"id", j.id},
                        {"kind", j.kind},
                        {"item", j.item},
                        {"scene", submitted.scene},
                        {"state", j.state},
                        {"created", j.created}});
        ids.push_back(j.id);
      }
      nlohmann::json summary = {{"scene", submitted.scene},
                                {"scene_manifest", submitted.scene_manifest},
                                {"uploaded_files", submitted.files_sent},
                                {"uploaded_bytes", submitted.bytes_sent},
                                {"jobs", jobs}};
      if (a.wait) {
        ASSIGN_OR_RETURN(auto final_jobs, Watch(*c, ids, ""));
        summary["jobs"] = nlohmann::json::array();
        for (const std::string& id : ids) summary["jobs"].push_back(JobJson(final_jobs[id]));
      }
      if (a.json) PrintJsonLine(summary.dump());
      return absl::OkStatus();
    };
  });
}

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
                       ConnectTo(watch->connection, watch->server));
      ASSIGN_OR_RETURN(auto jobs, Watch(*c, watch->ids, watch->scene));
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

// `jobs`: the job queue as a table, with queue statistics.
void AddJobsCommand(CLI::App& app, Action* action) {
  struct JobsArgs {
    std::string server = kDefaultServer, scene, state, page_token;
    ConnectionFlags connection;
    int limit = 50;
    bool json = false;
  };
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
  l->callback([list, action] {
    *action = [list]() -> absl::Status {
      ASSIGN_OR_RETURN(std::unique_ptr<client::Client> c,
                       ConnectTo(list->connection, list->server));
      v1::ListJobsRequest request;
      request.set_scene(list->scene);
      request.set_limit(list->limit);
      request.set_page_token(list->page_token);
      if (!list->state.empty()) {
        for (int st = v1::JOB_STATE_QUEUED; st <= v1::JOB_STATE_CANCELLED; ++st) {
          if (scheduler::StateName(static_cast<v1::JobState>(st)) == list->state)
            request.set_state(static_cast<v1::JobState>(st));
        }
      }
      v1::ListJobsResponse response;
      RETURN_IF_ERROR(client::Call(*c, "scheduler", [&](grpc::ClientContext* context) {
        return client::SchedulerStub(*c).ListJobs(context, request, &response);
      }));
      // Queue-wide figures are monitoring (admins); a client token lists its own jobs only.
      v1::QueueStats stats;
      const absl::Status stats_status =
          client::Call(*c, "scheduler", [&](grpc::ClientContext* context) {
            return client::SchedulerStub(*c).GetQueueStats(context, v1::GetQueueStatsRequest(),
                                                           &stats);
          });
      if (!stats_status.ok() && !absl::IsPermissionDenied(stats_status)) return stats_status;
      const bool has_stats = stats_status.ok();
      std::printf("%-17s %-22s %-16s %-9s %-3s %s\n", "JOB", "KIND", "SCENE", "STATE", "TRY",
                  "PROGRESS / ERROR");
      nlohmann::json jobs = nlohmann::json::array();
      std::vector<const v1::Job*> ordered;  // oldest first
      for (auto it = response.jobs().rbegin(); it != response.jobs().rend(); ++it)
        ordered.push_back(&*it);
      // With --scene the jobs print as their DAG: children indented under their first input.
      std::vector<std::pair<int, const v1::Job*>> rows;
      if (list->scene.empty()) {
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
      nlohmann::json by_state = nlohmann::json::object();
      std::string line;
      for (const char* state :
           {"queued", "leased", "running", "succeeded", "failed", "cancelled"}) {
        auto it = stats.jobs_by_state().find(state);
        const int64_t n = it == stats.jobs_by_state().end() ? 0 : it->second;
        by_state[state] = n;
        absl::StrAppend(&line, state, " ", n, "  ");
      }
      if (has_stats)
        std::printf("queue: %s| scenes %lld | oldest queued %.1f s\n", line.c_str(),
                    static_cast<long long>(stats.scenes()), stats.oldest_queued_age_ms() / 1000.0);
      if (!response.next_page_token().empty())
        std::printf("more: --page-token %s\n", response.next_page_token().c_str());
      if (list->json)
        PrintJsonLine(
            nlohmann::json({{"jobs", jobs},
                            {"next_page_token", response.next_page_token()},
                            {"stats", has_stats ? nlohmann::json{{"jobs_by_state", by_state},
                                                                 {"scenes", stats.scenes()},
                                                                 {"oldest_queued_age_ms",
                                                                  stats.oldest_queued_age_ms()}}
                                                : nlohmann::json(nullptr)}})
                .dump());
      return absl::OkStatus();
    };
  });
}

// `fetch`: downloads a scene's latest outputs or one job's.
void AddFetchCommand(CLI::App& app, Action* action) {
  struct FetchArgs {
    std::string server = kDefaultServer, store, id, scene, out;
    ConnectionFlags connection;
    bool json = false;
  };
  auto fetch = std::make_shared<FetchArgs>();
  CLI::App* f = app.add_subcommand(
      "fetch",
      "Download results: a scene's latest output of every stage (--scene NAME: into "
      "OUT/<stage>/, per-item stages into OUT/<stage>/<item>/), or one finished job's output");
  f->add_option("id", fetch->id, "Job id (instead of --scene)");
  f->add_option("--scene", fetch->scene, "Scene name: every stage's latest output");
  f->add_option("--out", fetch->out, "Directory to write the files to")->required();
  f->add_option("--server", fetch->server, "Scheduler address")->capture_default_str();
  AddConnectionFlags(f, &fetch->connection);
  f->add_option("--store", fetch->store, "Store address (default: --server)");
  f->add_flag("--json", fetch->json, "Print a JSON summary as the last stdout line");
  f->callback([fetch, action] {
    *action = [fetch]() -> absl::Status {
      if (fetch->id.empty() == fetch->scene.empty())
        return absl::InvalidArgumentError("give a job id or --scene NAME (one of them)");
      ASSIGN_OR_RETURN(std::unique_ptr<client::Client> c,
                       ConnectTo(fetch->connection, fetch->server, fetch->store));
      // (stage output, target directory)
      std::vector<std::pair<client::StageOutput, std::string>> outputs;
      if (!fetch->scene.empty()) {
        ASSIGN_OR_RETURN(std::vector<client::StageOutput> stage_outputs,
                         c->SceneOutputs(fetch->scene));
        for (const client::StageOutput& o : stage_outputs) {
          std::filesystem::path dir = std::filesystem::path(fetch->out) / o.kind;
          if (o.item >= 0) dir /= std::to_string(o.item);
          outputs.emplace_back(o, dir.string());
        }
        if (outputs.empty())
          return absl::FailedPreconditionError(
              absl::StrCat("scene ", fetch->scene, " has no finished stage yet"));
      } else {
        v1::GetJobRequest request;
        request.set_job_id(fetch->id);
        v1::Job job;
        RETURN_IF_ERROR(client::Call(*c, "scheduler", [&](grpc::ClientContext* context) {
          return client::SchedulerStub(*c).GetJob(context, request, &job);
        }));
        if (job.state() != v1::JOB_STATE_SUCCEEDED)
          return absl::FailedPreconditionError(
              absl::StrCat("job ", fetch->id, " is ", scheduler::StateName(job.state()),
                           ", not succeeded; nothing to fetch yet"));
        outputs.emplace_back(
            client::StageOutput{job.kind(), job.item(), job.id(), job.output_manifest().hash(),
                                job.output_manifest().size_bytes()},
            fetch->out);
      }
      nlohmann::json fetched = nlohmann::json::array();
      int64_t files = 0, bytes = 0;
      for (const auto& [o, dir] : outputs) {
        ASSIGN_OR_RETURN(client::Transfer t, c->FetchOutput(o, dir));
        files += t.files;
        bytes += t.bytes;
        fetched.push_back({{"kind", o.kind},
                           {"item", o.item},
                           {"job", o.job_id},
                           {"files", t.files},
                           {"out", dir}});
      }
      std::fprintf(stderr, "fetch: %lld files (%.1f MB) of %zu outputs into %s\n",
                   static_cast<long long>(files), bytes / 1e6, outputs.size(), fetch->out.c_str());
      if (fetch->json)
        PrintJsonLine(nlohmann::json({{"job", fetch->id},
                                      {"scene", fetch->scene},
                                      {"outputs", fetched},
                                      {"files", files},
                                      {"bytes", bytes},
                                      {"out", fetch->out}})
                          .dump());
      return absl::OkStatus();
    };
  });
}

// `cancel`: cancels a job and its dependants, or a scene's unfinished jobs.
void AddCancelCommand(CLI::App& app, Action* action) {
  struct CancelArgs {
    std::string server = kDefaultServer, id, scene;
    ConnectionFlags connection;
  };
  auto cancel = std::make_shared<CancelArgs>();
  CLI::App* k = app.add_subcommand(
      "cancel",
      "Cancel a job (queued: at once; running: its worker stops at the next heartbeat) and every "
      "job depending on it, or with --scene every unfinished job of a scene");
  k->add_option("id", cancel->id, "Job id (instead of --scene)");
  k->add_option("--scene", cancel->scene, "Scene name: cancel all its unfinished jobs");
  k->add_option("--server", cancel->server, "Scheduler address")->capture_default_str();
  AddConnectionFlags(k, &cancel->connection);
  k->callback([cancel, action] {
    *action = [cancel]() -> absl::Status {
      if (cancel->id.empty() == cancel->scene.empty())
        return absl::InvalidArgumentError("give a job id or --scene NAME (one of them)");
      ASSIGN_OR_RETURN(std::unique_ptr<client::Client> c,
                       ConnectTo(cancel->connection, cancel->server));
      std::vector<v1::Job> jobs;
      if (!cancel->scene.empty()) {
        v1::CancelSceneRequest request;
        request.set_scene(cancel->scene);
        v1::CancelSceneResponse response;
        RETURN_IF_ERROR(client::Call(*c, "scheduler", [&](grpc::ClientContext* context) {
          return client::SchedulerStub(*c).CancelScene(context, request, &response);
        }));
        jobs.assign(response.jobs().begin(), response.jobs().end());
        std::fprintf(stderr, "scene %s: %zu unfinished jobs cancelled or asked to stop\n",
                     cancel->scene.c_str(), jobs.size());
      } else {
        v1::CancelJobRequest request;
        request.set_job_id(cancel->id);
        v1::Job job;
        RETURN_IF_ERROR(client::Call(*c, "scheduler", [&](grpc::ClientContext* context) {
          return client::SchedulerStub(*c).CancelJob(context, request, &job);
        }));
        jobs.push_back(job);
      }
      for (const v1::Job& job : jobs) {
        std::fprintf(stderr, "job %s %s: %s%s\n", job.id().c_str(), KindLabel(job).c_str(),
                     scheduler::StateName(job.state()).c_str(),
                     job.cancel_requested() && !IsFinalState(job.state())
                         ? " (cancellation requested; the worker stops at its next heartbeat)"
                         : "");
      }
      return absl::OkStatus();
    };
  });
}

}  // namespace

void AddClientCommands(CLI::App& app, Action* action) {
  AddSubmitCommand(app, action);
  AddWatchCommand(app, action);
  AddJobsCommand(app, action);
  AddFetchCommand(app, action);
  AddCancelCommand(app, action);
}

}  // namespace instascene::cli
