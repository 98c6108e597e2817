#include "clients/cli/job_view.h"

#include <cstdio>
#include <functional>
#include <set>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/cli/progress.h"
#include "common/core/status.h"
#include "common/rpc/status.h"
#include "instascene/client/services.h"
#include "services/scheduler/job_proto.h"

namespace instascene::cli {

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

std::string KindLabel(const v1::Job& j) {
  return j.item() >= 0 ? absl::StrCat(j.kind(), "[", j.item(), "]") : j.kind();
}

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

absl::StatusOr<std::map<std::string, v1::Job>> WatchJobs(client::Client& c,
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

}  // namespace instascene::cli
