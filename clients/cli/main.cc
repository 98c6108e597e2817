// instascene: offline pipeline commands, the embedded server and clients of the services.
#include <cstdio>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "clients/cli/cli.h"

namespace instascene::cli {

void PrintJsonLine(const std::string& json) {
  std::fflush(stderr);
  std::printf("%s\n", json.c_str());
  std::fflush(stdout);
}

absl::StatusOr<std::vector<double>> ParseNumbers(const std::string& spec, size_t count,
                                                 const std::string& flag, const std::string& form) {
  std::vector<double> values;
  for (absl::string_view p : absl::StrSplit(spec, ',')) {
    double v = 0;
    if (!absl::SimpleAtod(p, &v))
      return absl::InvalidArgumentError(absl::StrCat(flag, ": not a number: '", p, "'"));
    values.push_back(v);
  }
  if (values.size() != count)
    return absl::InvalidArgumentError(absl::StrCat(flag, " must be ", form));
  return values;
}

}  // namespace instascene::cli

namespace {

int Run(int argc, char** argv) {
  using namespace instascene::cli;
  CLI::App app{
      "instascene: decompose captured Gaussian-splat scenes into complete object instances"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "instascene 0.1.0");
  Action action;
  AddSynthCommand(app, &action);
  AddImportCommand(app, &action);
  AddConvertCommand(app, &action);
  AddInfoCommand(app, &action);
  AddRenderCommand(app, &action);
  AddDecomposeCommand(app, &action);
  AddTrainCommands(app, &action);
  AddQueryCommand(app, &action);
  AddCompleteCommand(app, &action);
  AddExportCommand(app, &action);
  AddEvalCommand(app, &action);
  AddBenchCommand(app, &action);
  AddServeCommand(app, &action);
  AddClientCommands(app, &action);
  AddObjectCommands(app, &action);
  AddTokenCommand(app, &action);
  AddGcCommand(app, &action);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  const absl::Status status = action ? action() : absl::InternalError("no command selected");
  if (!status.ok()) {
    std::fprintf(stderr, "instascene: error: %s\n", status.ToString().c_str());
    return 1;
  }
  return 0;
}

}  // namespace

// Errors are statuses; an exception reaching here (e.g. std::bad_alloc) still ends with the
// one-line reason and a non-zero exit instead of an abort.
int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "instascene: error: %s\n", e.what());
    return 1;
  }
}
