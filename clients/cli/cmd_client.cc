// `instascene submit | fetch | cancel`: a scene's pipeline on a running server (`watch` and
// `jobs`: cmd_jobs.cc).
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
#include "clients/cli/job_view.h"
#include "clients/cli/progress.h"
#include "common/core/status.h"
#include "common/rpc/status.h"
#include "common/scene/image_io.h"
#include "common/scene/scene.h"
#include "instascene/client/services.h"
#include "services/scheduler/job_proto.h"

namespace instascene::cli {
namespace {

struct SubmitArgs {
  std::string server = kDefaultServer, store, scene, name, params;
  ConnectionFlags connection;
  std::vector<std::string> stages;
  int priority = 0, iterations = 0;
  bool iterations_given = false;
  bool json = false, wait = false;
};

// The stage parameters: --params, with --iterations as train.iterations.
absl::StatusOr<nlohmann::json> SubmitParameters(const SubmitArgs& a) {
  nlohmann::json params = nlohmann::json::object();
  if (!a.params.empty()) {
    params = nlohmann::json::parse(a.params, nullptr, false);
    if (params.is_discarded() || !params.is_object())
      return absl::InvalidArgumentError("--params is not a JSON object");
  }
  if (a.iterations_given) params["train"]["iterations"] = a.iterations;
  return params;
}

// The submitted jobs, printed, as JSON; their ids into `ids`.
nlohmann::json SubmittedJobs(const client::SubmitResult& submitted, std::vector<std::string>* ids) {
  nlohmann::json jobs = nlohmann::json::array();
  for (const client::SubmittedJob& j : submitted.jobs) {
    std::fprintf(stderr, "job %s %-9s %s%s\n", j.id.c_str(), j.kind.c_str(), j.state.c_str(),
                 j.created ? "" : " (existing job)");
    jobs.push_back({{"id", j.id},
                    {"kind", j.kind},
                    {"item", j.item},
                    {"scene", submitted.scene},
                    {"state", j.state},
                    {"created", j.created}});
    ids->push_back(j.id);
  }
  return jobs;
}

absl::Status RunSubmit(const SubmitArgs& a) {
  ASSIGN_OR_RETURN(const nlohmann::json params, SubmitParameters(a));
  {  // every image and mask against its camera (headers only) before anything is sent
    ASSIGN_OR_RETURN(Scene scene, ReadScene(a.scene));
    RETURN_IF_ERROR(CheckViewFiles(scene));
  }
  ASSIGN_OR_RETURN(std::unique_ptr<client::Client> c,
                   ConnectClient(a.connection, a.server, a.store));
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
  std::vector<std::string> ids;
  nlohmann::json summary = {{"scene", submitted.scene},
                            {"scene_manifest", submitted.scene_manifest},
                            {"uploaded_files", submitted.files_sent},
                            {"uploaded_bytes", submitted.bytes_sent},
                            {"jobs", SubmittedJobs(submitted, &ids)}};
  if (a.wait) {
    ASSIGN_OR_RETURN(auto final_jobs, WatchJobs(*c, ids, ""));
    summary["jobs"] = nlohmann::json::array();
    for (const std::string& id : ids) summary["jobs"].push_back(JobJson(final_jobs[id]));
  }
  if (a.json) PrintJsonLine(summary.dump());
  return absl::OkStatus();
}

// `submit`: uploads a scene and submits its pipeline.
void AddSubmitCommand(CLI::App& app, Action* action) {
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
    *action = [submit] { return RunSubmit(*submit); };
  });
}

struct FetchArgs {
  std::string server = kDefaultServer, store, id, scene, out;
  ConnectionFlags connection;
  bool json = false;
};

// (stage output, target directory) pairs: a scene's latest output of every stage, or one
// succeeded job's output.
using Outputs = std::vector<std::pair<client::StageOutput, std::string>>;
absl::StatusOr<Outputs> OutputsToFetch(const FetchArgs& a, client::Client& c) {
  Outputs outputs;
  if (!a.scene.empty()) {
    ASSIGN_OR_RETURN(std::vector<client::StageOutput> stage_outputs, c.SceneOutputs(a.scene));
    for (const client::StageOutput& o : stage_outputs) {
      std::filesystem::path dir = std::filesystem::path(a.out) / o.kind;
      if (o.item >= 0) dir /= std::to_string(o.item);
      outputs.emplace_back(o, dir.string());
    }
    if (outputs.empty())
      return absl::FailedPreconditionError(
          absl::StrCat("scene ", a.scene, " has no finished stage yet"));
    return outputs;
  }
  v1::GetJobRequest request;
  request.set_job_id(a.id);
  v1::Job job;
  RETURN_IF_ERROR(client::Call(c, "scheduler", [&](grpc::ClientContext* context) {
    return client::SchedulerStub(c).GetJob(context, request, &job);
  }));
  if (job.state() != v1::JOB_STATE_SUCCEEDED)
    return absl::FailedPreconditionError(absl::StrCat("job ", a.id, " is ",
                                                      scheduler::StateName(job.state()),
                                                      ", not succeeded; nothing to fetch yet"));
  outputs.emplace_back(
      client::StageOutput{job.kind(), job.item(), job.id(), job.output_manifest().hash(),
                          job.output_manifest().size_bytes()},
      a.out);
  return outputs;
}

absl::Status RunFetch(const FetchArgs& a) {
  if (a.id.empty() == a.scene.empty())
    return absl::InvalidArgumentError("give a job id or --scene NAME (one of them)");
  ASSIGN_OR_RETURN(std::unique_ptr<client::Client> c,
                   ConnectClient(a.connection, a.server, a.store));
  ASSIGN_OR_RETURN(const Outputs outputs, OutputsToFetch(a, *c));
  nlohmann::json fetched = nlohmann::json::array();
  int64_t files = 0, bytes = 0;
  for (const auto& [o, dir] : outputs) {
    ASSIGN_OR_RETURN(client::Transfer t, c->FetchOutput(o, dir));
    files += t.files;
    bytes += t.bytes;
    fetched.push_back(
        {{"kind", o.kind}, {"item", o.item}, {"job", o.job_id}, {"files", t.files}, {"out", dir}});
  }
  std::fprintf(stderr, "fetch: %lld files (%.1f MB) of %zu outputs into %s\n",
               static_cast<long long>(files), bytes / 1e6, outputs.size(), a.out.c_str());
  if (a.json)
    PrintJsonLine(nlohmann::json({{"job", a.id},
                                  {"scene", a.scene},
                                  {"outputs", fetched},
                                  {"files", files},
                                  {"bytes", bytes},
                                  {"out", a.out}})
                      .dump());
  return absl::OkStatus();
}

// `fetch`: downloads a scene's latest outputs or one job's.
void AddFetchCommand(CLI::App& app, Action* action) {
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
  f->callback([fetch, action] { *action = [fetch] { return RunFetch(*fetch); }; });
}

struct CancelArgs {
  std::string server = kDefaultServer, id, scene;
  ConnectionFlags connection;
};

// `cancel`'s work: the scene's unfinished jobs or one job and its dependants, then each state.
absl::Status RunCancel(const CancelArgs& args) {
  if (args.id.empty() == args.scene.empty())
    return absl::InvalidArgumentError("give a job id or --scene NAME (one of them)");
  ASSIGN_OR_RETURN(std::unique_ptr<client::Client> c, ConnectClient(args.connection, args.server));
  std::vector<v1::Job> jobs;
  if (!args.scene.empty()) {
    v1::CancelSceneRequest request;
    request.set_scene(args.scene);
    v1::CancelSceneResponse response;
    RETURN_IF_ERROR(client::Call(*c, "scheduler", [&](grpc::ClientContext* context) {
      return client::SchedulerStub(*c).CancelScene(context, request, &response);
    }));
    jobs.assign(response.jobs().begin(), response.jobs().end());
    std::fprintf(stderr, "scene %s: %zu unfinished jobs cancelled or asked to stop\n",
                 args.scene.c_str(), jobs.size());
  } else {
    v1::CancelJobRequest request;
    request.set_job_id(args.id);
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
}

// `cancel`: cancels a job and its dependants, or a scene's unfinished jobs.
void AddCancelCommand(CLI::App& app, Action* action) {
  auto cancel = std::make_shared<CancelArgs>();
  CLI::App* k = app.add_subcommand(
      "cancel",
      "Cancel a job (queued: at once; running: its worker stops at the next heartbeat) and every "
      "job depending on it, or with --scene every unfinished job of a scene");
  k->add_option("id", cancel->id, "Job id (instead of --scene)");
  k->add_option("--scene", cancel->scene, "Scene name: cancel all its unfinished jobs");
  k->add_option("--server", cancel->server, "Scheduler address")->capture_default_str();
  AddConnectionFlags(k, &cancel->connection);
  k->callback([cancel, action] { *action = [cancel] { return RunCancel(*cancel); }; });
}

struct DeleteArgs {
  std::string server = kDefaultServer, scene;
  bool json = false;
  ConnectionFlags connection;
};

// `delete`: a scene's jobs, once all of them have ended (its blobs go with the next `gc`).
void AddDeleteCommand(CLI::App& app, Action* action) {
  auto args = std::make_shared<DeleteArgs>();
  CLI::App* d = app.add_subcommand(
      "delete",
      "Delete a scene's jobs once all of them have ended (cancel the scene first); its results' "
      "blobs go with the store's next garbage collection (`instascene gc`)");
  d->add_option("--scene", args->scene, "Scene name")->required();
  d->add_option("--server", args->server, "Scheduler address")->capture_default_str();
  d->add_flag("--json", args->json, "Print a JSON summary as the last stdout line");
  AddConnectionFlags(d, &args->connection);
  d->callback([args, action] {
    *action = [args]() -> absl::Status {
      ASSIGN_OR_RETURN(std::unique_ptr<client::Client> c,
                       ConnectClient(args->connection, args->server));
      v1::DeleteSceneRequest request;
      request.set_scene(args->scene);
      v1::DeleteSceneResponse response;
      RETURN_IF_ERROR(client::Call(*c, "scheduler", [&](grpc::ClientContext* context) {
        return client::SchedulerStub(*c).DeleteScene(context, request, &response);
      }));
      std::fprintf(stderr, "scene %s: %lld jobs deleted%s\n", args->scene.c_str(),
                   static_cast<long long>(response.deleted_jobs()),
                   response.kept_jobs() > 0
                       ? absl::StrCat(", ", response.kept_jobs(),
                                      " kept (another scene's unfinished jobs need them)")
                             .c_str()
                       : "");
      if (args->json)
        PrintJsonLine(nlohmann::json({{"scene", args->scene},
                                      {"deleted_jobs", response.deleted_jobs()},
                                      {"kept_jobs", response.kept_jobs()}})
                          .dump());
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
  AddDeleteCommand(app, action);
}

}  // namespace instascene::cli
