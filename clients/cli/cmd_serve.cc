// `instascene serve`: store + scheduler + stage services in one process (the embedded default).
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "clients/cli/cli.h"
#include "common/core/status.h"
#include "services/node/node_flags.h"
#include "services/node/stage_services.h"
#include "services/stages/all_stages.h"

namespace instascene::cli {

void AddServeCommand(CLI::App& app, Action* action) {
  struct Args {
    node::NodeOptions options;
    std::string workers = "all";
  };
  auto args = std::make_shared<Args>();
  std::vector<std::string> names;
  for (const node::StageService& s : node::AllStageServices()) names.push_back(s.name);
  CLI::App* cmd = app.add_subcommand(
      "serve",
      "Run the store, the scheduler and the stage services (workers) in one process "
      "(filesystem store + SQLite queue under --data); SIGTERM drains gracefully");
  node::AddNodeFlags(*cmd, &args->options, false, false);
  cmd->add_option("--workers", args->workers,
                  absl::StrCat("Which stage services to run here: all, none, or a comma list of ",
                               absl::StrJoin(names, ", ")))
      ->capture_default_str();
  cmd->callback([args, action] {
    *action = [args]() -> absl::Status {
      pipeline::StageRegistry stages;
      RETURN_IF_ERROR(stages::RegisterStages(&stages));
      const std::vector<node::StageService> services = node::AllStageServices();
      node::NodeOptions o = args->options;
      if (args->workers == "all") {
        for (const node::StageService& s : services) o.workers.push_back(s.name);
      } else if (args->workers != "none") {
        o.workers = absl::StrSplit(args->workers, ',', absl::SkipEmpty());
      }
      return node::RunNode(o, stages, services);
    };
  });
}

}  // namespace instascene::cli
