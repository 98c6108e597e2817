// `instascene submit | watch | jobs | fetch | cancel`: clients of a running server.
#include <unistd.h>

#include <cstdio>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/cli/cli.h"
#include "clients/cli/progress.h"
#include "common/core/status.h"
#include "common/rpc/server.h"
#include "common/rpc/status.h"
#include "common/store/manifest.h"
#include "instascene/v1/scheduler.grpc.pb.h"
#include "services/scheduler/job_proto.h"
#include "services/store/remote_blob_store.h"

namespace instascene::cli {
namespace {

constexpr char kDefaultServer[] = "127.0.0.1:50051";

struct Connection {
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<v1::Scheduler::Stub> scheduler;
};

Connection ConnectTo(const std::string& address) {
  Connection c;
  c.channel = rpc::Connect(address);
  c.scheduler = v1::Scheduler::NewStub(c.channel);
  return c;
}

void SetDeadline(grpc::ClientContext* context, int seconds = 30) {
  context->set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(seconds));
}

absl::Status Call(const grpc::Status& status, const std::string& server) {
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE ||
      status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED)
    return absl::UnavailableError(absl::StrCat("server ", server,
                                               " unreachable: ", status.error_message(),
                                               " (is `instascene serve` running?)"));
  return rpc::FromGrpcStatus(status);
}

nlohmann::json JobJson(const v1::Job& j) {
  nlohmann::json out = {{"id", j.id()},
                        {"kind", j.kind()},
                        {"scene", j.scene()},
                        {"state", scheduler::StateName(j.state())},
                        {"attempts", j.attempts()},
                        {"depends_on", j.depends_on()},
                        {"error", j.error()},
                        {"phase", j.progress().phase()},
                        {"step", j.progress().step()},
                        {"total", j.progress().total()}};
  if (j.has_output_manifest())
    out["output_manifest"] = rpc::FromProto(j.output_manifest()).ToString();
  return out;
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
absl::StatusOr<std::map<std::string, v1::Job>> Watch(Connection& c, const std::string& server,
                                                     const std::vector<std::string>& ids,
                                                     const std::string& scene) {
  v1::WatchJobsRequest request;
  for (const std::string& id : ids) request.add_job_ids(id);
  request.set_scene(scene);
  grpc::ClientContext context;
  std::unique_ptr<grpc::ClientReader<v1::Job>> reader(c.scheduler->WatchJobs(&context, request));
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
  RETURN_IF_ERROR(Call(reader->Finish(), server));
  return last;
}

}  // namespace

void AddClientCommands(CLI::App& app, Action* action) {
  // submit
  struct SubmitArgs {
    std::string server = kDefaultServer, store, scene, name, params;
    int priority = 0, iterations = 0;
    bool json = false, wait = false;
  };
  auto submit = std::make_shared<SubmitArgs>();
  CLI::App* s =
      app.add_subcommand("submit",
                         "Upload a scene (only the blobs the store lacks) and submit its pipeline "
                         "decompose -> train -> segment; prints the job ids");
  s->add_option("--scene", submit->scene, "Scene directory")->required();
  s->add_option("--server", submit->server, "Scheduler address")->capture_default_str();
  s->add_option("--store", submit->store, "Store address (default: --server)");
  s->add_option("--name", submit->name, "Scene name shown in job lists (default: directory name)");
  s->add_option("--params", submit->params,
                R"(Stage parameters as JSON, e.g. '{"train":{"iterations":500}}')");
  s->add_option("--iterations", submit->iterations, "Shortcut for train.iterations");
  s->add_option("--priority", submit->priority, "Higher runs first (interactive requests)");
  s->add_flag("--wait", submit->wait, "Watch the jobs until they finish");
  s->add_flag("--json", submit->json, "Print {\"scene\", \"jobs\", ...} as the last stdout line");
  s->callback([submit, action] {
    *action = [submit]() -> absl::Status {
      const SubmitArgs& a = *submit;
      nlohmann::json params = nlohmann::json::object();
      if (!a.params.empty()) {
        params = nlohmann::json::parse(a.params, nullptr, false);
        if (params.is_discarded() || !params.is_object())
          return absl::InvalidArgumentError("--params is not a JSON object");
      }
      if (a.iterations > 0) params["train"]["iterations"] = a.iterations;
      ASSIGN_OR_RETURN(store::Manifest manifest, store::SceneManifestFromDirectory(a.scene));
      Connection c = ConnectTo(a.server);
      absl::StatusOr<std::unique_ptr<store_service::RemoteBlobStore>> connected =
          store_service::RemoteBlobStore::Connect(
              a.store.empty() ? c.channel : rpc::Connect(a.store), 5000);
      if (!connected.ok())
        return absl::UnavailableError(absl::StrCat("store ", a.store.empty() ? a.server : a.store,
                                                   " unreachable: ", connected.status().message(),
                                                   " (is `instascene serve` running?)"));
      std::unique_ptr<store_service::RemoteBlobStore> blobs = std::move(*connected);
      ProgressBar bar("upload");
      int64_t last_mb = -1;
      ASSIGN_OR_RETURN(
          store::UploadReport upload,
          store::UploadManifest(*blobs, manifest, a.scene, [&](int64_t done, int64_t total) {
            if (done / (1 << 20) == last_mb && done != total) return;
            last_mb = done / (1 << 20);
            bar.Update(static_cast<int>(done >> 10), static_cast<int>(total >> 10));
          }));
      std::fprintf(stderr, "upload: %lld files (%.1f MB) sent, %lld already in the store\n",
                   static_cast<long long>(upload.files_sent), upload.bytes_sent / 1e6,
                   static_cast<long long>(upload.files_skipped));
      v1::SubmitPipelineRequest request;
      rpc::ToProto(upload.manifest, request.mutable_scene_manifest());
      const std::string name =
          a.name.empty() ? std::filesystem::path(a.scene).lexically_normal().filename().string()
                         : a.name;
      request.set_scene(name);
      request.set_parameters_json(params.dump());
      request.set_priority(a.priority);
      v1::SubmitPipelineResponse response;
      grpc::ClientContext context;
      SetDeadline(&context);
      RETURN_IF_ERROR(Call(c.scheduler->SubmitPipeline(&context, request, &response), a.server));
      nlohmann::json jobs = nlohmann::json::array();
      for (int i = 0; i < response.jobs_size(); ++i) {
        const v1::Job& j = response.jobs(i);
        std::fprintf(stderr, "job %s %-9s %s%s\n", j.id().c_str(), j.kind().c_str(),
                     scheduler::StateName(j.state()).c_str(),
                     response.created(i) ? "" : " (existing job)");
        nlohmann::json jj = JobJson(j);
        jj["created"] = response.created(i);
        jobs.push_back(jj);
      }
      nlohmann::json summary = {{"scene", name},
                                {"scene_manifest", upload.manifest.ToString()},
                                {"uploaded_files", upload.files_sent},
                                {"uploaded_bytes", upload.bytes_sent},
                                {"jobs", jobs}};
      if (a.wait) {
        std::vector<std::string> ids;
        for (const v1::Job& j : response.jobs()) ids.push_back(j.id());
        ASSIGN_OR_RETURN(auto final_jobs, Watch(c, a.server, ids, ""));
        summary["jobs"] = nlohmann::json::array();
        for (const std::string& id : ids) summary["jobs"].push_back(JobJson(final_jobs[id]));
      }
      if (a.json) PrintJsonLine(summary.dump());
      return absl::OkStatus();
    };
  });

  // watch
  struct WatchArgs {
    std::string server = kDefaultServer, scene;
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
  w->add_flag("--json", watch->json, "Print the final jobs as one JSON object");
  w->callback([watch, action] {
    *action = [watch]() -> absl::Status {
      if (watch->ids.empty() && watch->scene.empty())
        return absl::InvalidArgumentError("give job ids or --scene");
      Connection c = ConnectTo(watch->server);
      ASSIGN_OR_RETURN(auto jobs, Watch(c, watch->server, watch->ids, watch->scene));
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

  // jobs
  struct JobsArgs {
    std::string server = kDefaultServer, scene, state;
    int limit = 50;
    bool json = false;
  };
  auto list = std::make_shared<JobsArgs>();
  CLI::App* l = app.add_subcommand("jobs", "The job queue as a table, with queue statistics");
  l->add_option("--server", list->server, "Scheduler address")->capture_default_str();
  l->add_option("--scene", list->scene, "Only this scene");
  l->add_option("--state", list->state, "Only this state")
      ->check(CLI::IsMember({"queued", "leased", "running", "succeeded", "failed", "cancelled"}));
  l->add_option("--limit", list->limit, "At most this many (newest first)");
  l->add_flag("--json", list->json, "Print {\"jobs\", \"stats\"} as the last stdout line");
  l->callback([list, action] {
    *action = [list]() -> absl::Status {
      Connection c = ConnectTo(list->server);
      v1::ListJobsRequest request;
      request.set_scene(list->scene);
      request.set_limit(list->limit);
      if (!list->state.empty()) {
        for (int st = v1::JOB_STATE_QUEUED; st <= v1::JOB_STATE_CANCELLED; ++st) {
          if (scheduler::StateName(static_cast<v1::JobState>(st)) == list->state)
            request.set_state(static_cast<v1::JobState>(st));
        }
      }
      v1::ListJobsResponse response;
      grpc::ClientContext context;
      SetDeadline(&context);
      RETURN_IF_ERROR(Call(c.scheduler->ListJobs(&context, request, &response), list->server));
      v1::QueueStats stats;
      grpc::ClientContext stats_context;
      SetDeadline(&stats_context);
      RETURN_IF_ERROR(
          Call(c.scheduler->GetQueueStats(&stats_context, v1::GetQueueStatsRequest(), &stats),
               list->server));
      std::printf("%-17s %-9s %-16s %-9s %-3s %s\n", "JOB", "KIND", "SCENE", "STATE", "TRY",
                  "PROGRESS / ERROR");
      nlohmann::json jobs = nlohmann::json::array();
      for (const v1::Job& j : response.jobs()) {
        std::printf("%-17s %-9s %-16s %-9s %d/%d %s\n", j.id().c_str(), j.kind().c_str(),
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
      std::printf("queue: %s| scenes %lld | oldest queued %.1f s\n", line.c_str(),
                  static_cast<long long>(stats.scenes()), stats.oldest_queued_age_ms() / 1000.0);
      if (list->json)
        PrintJsonLine(nlohmann::json({{"jobs", jobs},
                                      {"stats",
                                       {{"jobs_by_state", by_state},
                                        {"scenes", stats.scenes()},
                                        {"oldest_queued_age_ms", stats.oldest_queued_age_ms()}}}})
                          .dump());
      return absl::OkStatus();
    };
  });

  // fetch
  struct FetchArgs {
    std::string server = kDefaultServer, store, id, out;
    bool json = false;
  };
  auto fetch = std::make_shared<FetchArgs>();
  CLI::App* f = app.add_subcommand(
      "fetch", "Download a finished job's output (e.g. the segment job: labels, instances/*.ply)");
  f->add_option("id", fetch->id, "Job id")->required();
  f->add_option("--out", fetch->out, "Directory to write the files to")->required();
  f->add_option("--server", fetch->server, "Scheduler address")->capture_default_str();
  f->add_option("--store", fetch->store, "Store address (default: --server)");
  f->add_flag("--json", fetch->json, "Print a JSON summary as the last stdout line");
  f->callback([fetch, action] {
    *action = [fetch]() -> absl::Status {
      Connection c = ConnectTo(fetch->server);
      v1::GetJobRequest request;
      request.set_job_id(fetch->id);
      v1::Job job;
      grpc::ClientContext context;
      SetDeadline(&context);
      RETURN_IF_ERROR(Call(c.scheduler->GetJob(&context, request, &job), fetch->server));
      if (job.state() != v1::JOB_STATE_SUCCEEDED)
        return absl::FailedPreconditionError(absl::StrCat("job ", fetch->id, " is ",
                                                          scheduler::StateName(job.state()),
                                                          ", not succeeded; nothing to fetch yet"));
      ASSIGN_OR_RETURN(std::unique_ptr<store_service::RemoteBlobStore> blobs,
                       store_service::RemoteBlobStore::Connect(
                           fetch->store.empty() ? c.channel : rpc::Connect(fetch->store), 5000));
      const store::Digest digest = rpc::FromProto(job.output_manifest());
      ASSIGN_OR_RETURN(store::Manifest manifest, store::ReadManifest(*blobs, digest));
      RETURN_IF_ERROR(store::MaterializeManifest(*blobs, manifest, fetch->out));
      std::fprintf(stderr, "fetch: %zu files (%.1f MB) of %s job %s into %s\n",
                   manifest.files.size(), manifest.TotalBytes() / 1e6, job.kind().c_str(),
                   job.id().c_str(), fetch->out.c_str());
      if (fetch->json)
        PrintJsonLine(nlohmann::json({{"job", fetch->id},
                                      {"kind", job.kind()},
                                      {"files", manifest.files.size()},
                                      {"bytes", manifest.TotalBytes()},
                                      {"out", fetch->out}})
                          .dump());
      return absl::OkStatus();
    };
  });

  // cancel
  struct CancelArgs {
    std::string server = kDefaultServer, id;
  };
  auto cancel = std::make_shared<CancelArgs>();
  CLI::App* k = app.add_subcommand(
      "cancel",
      "Cancel a job (queued: at once; running: its worker stops at the next heartbeat); "
      "jobs depending on it are cancelled too");
  k->add_option("id", cancel->id, "Job id")->required();
  k->add_option("--server", cancel->server, "Scheduler address")->capture_default_str();
  k->callback([cancel, action] {
    *action = [cancel]() -> absl::Status {
      Connection c = ConnectTo(cancel->server);
      v1::CancelJobRequest request;
      request.set_job_id(cancel->id);
      v1::Job job;
      grpc::ClientContext context;
      SetDeadline(&context);
      RETURN_IF_ERROR(Call(c.scheduler->CancelJob(&context, request, &job), cancel->server));
      std::fprintf(stderr, "job %s: %s%s\n", job.id().c_str(),
                   scheduler::StateName(job.state()).c_str(),
                   job.cancel_requested() && !IsFinalState(job.state())
                       ? " (cancellation requested; the worker stops at its next heartbeat)"
                       : "");
      return absl::OkStatus();
    };
  });
}

}  // namespace instascene::cli
