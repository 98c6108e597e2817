// `instascene export`: robot-ready artefacts of completed objects, offline (the `export` stage's
// code on the folders `instascene complete` or `instascene run` wrote), so that a completion can be
// exported again (other density, collision parts, ...) without running the pipeline again.
#include <charconv>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <system_error>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "clients/cli/cli.h"
#include "clients/cli/progress.h"
#include "clients/cli/stage_flags.h"
#include "common/core/file_io.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "services/objects/stage.h"

namespace instascene::cli {
namespace {
namespace fs = std::filesystem;

// The completed objects under `dir`: its sub-folders named by a number (an object id as
// `instascene complete` names them, or an item as `instascene run` does) that hold a manifest,
// keyed "complete/<number>" as the export stage's input.
absl::StatusOr<std::map<std::string, std::string>> CompletedObjects(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    return absl::NotFoundError(absl::StrCat("--objects ", dir, ": not a directory"));
  std::map<std::string, std::string> inputs;
  for (const fs::directory_entry& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    int64_t number = -1;
    const auto [end, error] = std::from_chars(name.data(), name.data() + name.size(), number);
    if (error != std::errc() || end != name.data() + name.size() || number < 0) continue;
    if (!fs::is_regular_file(e.path() / "manifest.json", ec)) continue;
    inputs[absl::StrCat("complete/", number)] = e.path().string();
  }
  if (ec) return absl::InternalError(absl::StrCat("--objects ", dir, ": ", ec.message()));
  if (inputs.empty())
    return absl::FailedPreconditionError(absl::StrCat(
        "--objects ", dir,
        ": no completed object (numbered folders with a manifest.json, as `instascene complete` "
        "writes them)"));
  return inputs;
}

}  // namespace

void AddExportCommand(CLI::App& app, Action* action) {
  struct Args {
    std::string scene, objects, out;
    StageFlags flags;
    int threads = 0;
    bool json = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "export",
      "Export completed objects as robot-ready artefacts (glTF/Draco, STL, URDF, MJCF, collision "
      "parts, surface samples; metres where the scene is metric) and the object catalogue");
  cmd->add_option("--scene", args->scene, "Scene directory (its scene.json gives the metric scale)")
      ->required();
  cmd->add_option("--objects", args->objects,
                  "Completed objects: the --out of `instascene complete`, or <run>/objects")
      ->required();
  cmd->add_option("--out", args->out,
                  "Output directory (one <id>/ folder per object, objects.json)")
      ->required();
  args->flags.Add(cmd, objects::ExportSpec());
  cmd->add_option("--threads", args->threads, "Threads (0 = all cores)");
  cmd->add_flag("--json", args->json, "Print the catalogue (objects.json) as the last stdout line");
  cmd->callback([args, action] {
    *action = [args]() -> absl::Status {
      Stopwatch watch;
      ASSIGN_OR_RETURN(nlohmann::json parameters, args->flags.Parameters());
      pipeline::StageContext c;
      c.scene_dir = args->scene;
      ASSIGN_OR_RETURN(c.inputs, CompletedObjects(args->objects));
      c.out_dir = args->out;
      c.parameters = parameters.value("export", nlohmann::json::object());
      c.num_threads = args->threads;
      ProgressBar bar("export");
      c.progress = [&bar](const pipeline::StageProgress& p) {
        bar.Update(static_cast<int>(p.step), static_cast<int>(p.total));
      };
      std::error_code ec;
      fs::create_directories(args->out, ec);
      if (ec) return absl::InternalError(absl::StrCat("--out ", args->out, ": ", ec.message()));
      RETURN_IF_ERROR(objects::ExportStage().run(c).status());
      const std::string catalogue = (fs::path(args->out) / "objects.json").string();
      ASSIGN_OR_RETURN(std::string text, ReadFileBounded(catalogue, 64 << 20));
      std::fprintf(stderr, "export: %zu objects in %.1f s -> %s\n", c.inputs.size(),
                   watch.ElapsedSeconds(), catalogue.c_str());
      if (args->json) PrintJsonLine(nlohmann::json::parse(text).dump());
      return absl::OkStatus();
    };
  });
}

}  // namespace instascene::cli
