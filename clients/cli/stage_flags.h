// clients/cli/stage_flags.h: command-line flags generated from stage parameter schemas, so that
// the offline commands accept exactly the parameters the services accept, with the same defaults
// and bounds (the stage's one codec validates both). Parameter `dbscan_eps` of a stage becomes
// --dbscan-eps; booleans that default to false are plain flags. Not thread-safe.
#pragma once

#include <CLI/CLI.hpp>

#include <map>
#include <string>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "services/pipeline/stage.h"

namespace instascene::cli {

class StageFlags {
 public:
  // Adds one flag per parameter of `spec` to `cmd`. Two stages of one command may not share a
  // parameter name (a programming error: throws).
  void Add(CLI::App* cmd, const pipeline::StageSpec& spec);
  // {"<kind>": {<the parameters given on the command line>}, ...}; InvalidArgument naming the
  // flag when a value does not parse as its type.
  absl::StatusOr<nlohmann::json> Parameters() const;

 private:
  struct Flag {
    std::string kind, flag;
    pipeline::ParamSpec spec;
    std::string text;  // the value given (options)
    bool set = false;  // plain boolean flags
    CLI::Option* option = nullptr;
  };
  std::map<std::string, Flag> flags_;  // by parameter name; node addresses stay stable
};

}  // namespace instascene::cli
