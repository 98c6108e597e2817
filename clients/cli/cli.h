// clients/cli/cli.h: the `instascene` command line. Each command lives in its own file and
// registers a CLI11 subcommand; errors are returned as absl::Status and printed once by main as a
// one-line reason with a non-zero exit code.
#pragma once

#include <CLI/CLI.hpp>

#include <functional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace instascene::cli {

// A subcommand's action, run after parsing when that subcommand was selected.
using Action = std::function<absl::Status()>;

void AddInfoCommand(CLI::App& app, Action* action);
void AddRenderCommand(CLI::App& app, Action* action);
void AddBenchCommand(CLI::App& app, Action* action);
void AddImportCommand(CLI::App& app, Action* action);
void AddConvertCommand(CLI::App& app, Action* action);
void AddSynthCommand(CLI::App& app, Action* action);
void AddEvalCommand(CLI::App& app, Action* action);
void AddDecomposeCommand(CLI::App& app, Action* action);
void AddTrainCommands(CLI::App& app, Action* action);  // train, segment, run
void AddQueryCommand(CLI::App& app, Action* action);
void AddCompleteCommand(CLI::App& app, Action* action);
void AddExportCommand(CLI::App& app, Action* action);
void AddServeCommand(CLI::App& app, Action* action);
void AddClientCommands(CLI::App& app, Action* action);  // submit, watch, jobs, fetch, cancel
void AddWatchCommand(CLI::App& app, Action* action);    // cmd_jobs.cc
void AddJobsCommand(CLI::App& app, Action* action);     // cmd_jobs.cc
void AddObjectCommands(CLI::App& app, Action* action);  // object, objects
void AddTokenCommand(CLI::App& app, Action* action);    // token create | revoke | list
void AddGcCommand(CLI::App& app, Action* action);       // the store's garbage collection

// Prints one JSON object as the last stdout line (the --json contract).
void PrintJsonLine(const std::string& json);

// Parses a comma-separated list of exactly `count` numbers given as `flag` (errors say "FLAG must
// be FORM", e.g. "--point must be X,Y,Z").
absl::StatusOr<std::vector<double>> ParseNumbers(const std::string& spec, size_t count,
                                                 const std::string& flag, const std::string& form);

}  // namespace instascene::cli
