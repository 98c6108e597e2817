// `instascene serve`: store + scheduler + workers in one process (the embedded default).
#include "clients/cli/cli.h"
#include "services/node/node_flags.h"

namespace instascene::cli {

void AddServeCommand(CLI::App& app, Action* action) {
  struct Args {
    node::NodeOptions options;
    std::string workers = "all";
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "serve",
      "Run the store, the scheduler and the decomposition and training workers in one process "
      "(filesystem store + SQLite queue under --data); SIGTERM drains gracefully");
  node::AddNodeFlags(*cmd, &args->options, false, false);
  cmd->add_option("--workers", args->workers,
                  "Which workers to run here: all, none, decompose, train")
      ->check(CLI::IsMember({"all", "none", "decompose", "train"}))
      ->capture_default_str();
  cmd->callback([args, action] {
    *action = [args]() -> absl::Status {
      node::NodeOptions o = args->options;
      o.run_decomposition = args->workers == "all" || args->workers == "decompose";
      o.run_training = args->workers == "all" || args->workers == "train";
      return node::RunNode(o);
    };
  });
}

}  // namespace instascene::cli
