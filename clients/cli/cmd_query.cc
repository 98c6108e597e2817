// `instascene query`: which instance is under a pixel (or at a 3D point), its Gaussians and its
// masks in the other views.
#include <cstdio>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "absl/strings/str_split.h"
#include "clients/cli/cli.h"
#include "common/core/status.h"
#include "common/core/timer.h"
#include "common/scene/image_io.h"
#include "services/objects/query_index.h"

namespace instascene::cli {

namespace {

struct QueryArgs {
  std::string scene, result, view = "0", pixel, point, ray, out;
  float max_distance = 0.02f;
  bool json = false;
};

// The index's answer to the one query the flags give: a click, a ray or a point.
absl::StatusOr<objects::QueryAnswer> Ask(const QueryArgs& a, const Scene& scene,
                                         const objects::QueryIndex& index) {
  if (!a.pixel.empty()) {
    ASSIGN_OR_RETURN(std::vector<double> values, ParseNumbers(a.pixel, 2, "--pixel", "X,Y"));
    ASSIGN_OR_RETURN(int view, ResolveView(scene, a.view));
    return index.Click(view, static_cast<int>(values[0]), static_cast<int>(values[1]));
  }
  if (!a.ray.empty()) {
    ASSIGN_OR_RETURN(std::vector<double> values,
                     ParseNumbers(a.ray, 6, "--ray", "OX,OY,OZ,DX,DY,DZ"));
    return index.Ray(Eigen::Vector3d(values[0], values[1], values[2]).cast<float>(),
                     Eigen::Vector3d(values[3], values[4], values[5]).cast<float>());
  }
  ASSIGN_OR_RETURN(std::vector<double> values, ParseNumbers(a.point, 3, "--point", "X,Y,Z"));
  return index.Point(Eigen::Vector3d(values[0], values[1], values[2]).cast<float>(),
                     a.max_distance);
}

// The instance's mask in every view that shows it, as <view>.png under `out`.
absl::Status WriteMasks(const std::string& out, const Scene& scene,
                        const objects::QueryIndex& index, const objects::QueryAnswer& answer) {
  std::filesystem::create_directories(out);
  for (const auto& [v, pixels] : answer.views) {
    std::vector<uint8_t> mask = index.Mask(answer.instance, v);
    LabelMap png{scene.views[v].camera.width, scene.views[v].camera.height,
                 std::vector<uint16_t>(mask.begin(), mask.end())};
    RETURN_IF_ERROR(
        WriteLabelMap((std::filesystem::path(out) / (scene.views[v].name + ".png")).string(), png));
  }
  return absl::OkStatus();
}

absl::Status RunQuery(const QueryArgs& a) {
  if (a.pixel.empty() + a.point.empty() + a.ray.empty() != 2) {
    return absl::InvalidArgumentError("give exactly one of --pixel, --point or --ray");
  }
  ASSIGN_OR_RETURN(Scene scene, ReadScene(a.scene));
  ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
  ASSIGN_OR_RETURN(SegmentationResult result, ReadResult(a.result, cloud.size()));
  Stopwatch build;
  ASSIGN_OR_RETURN(std::unique_ptr<objects::QueryIndex> index,
                   objects::QueryIndex::Build(scene, cloud, result));
  const double build_ms = build.ElapsedMs();
  Stopwatch click;
  ASSIGN_OR_RETURN(const objects::QueryAnswer answer, Ask(a, scene, *index));
  const double click_ms = click.ElapsedMs();
  if (!a.out.empty() && answer.instance != 0) {
    RETURN_IF_ERROR(WriteMasks(a.out, scene, *index, answer));
  }
  std::printf(
      "instance %u: %zu Gaussians, visible in %zu views (index built in %.0f ms, query %.3f ms)\n",
      answer.instance, answer.gaussians, answer.views.size(), build_ms, click_ms);
  if (a.json) {
    nlohmann::json views = nlohmann::json::array();
    for (const auto& [v, pixels] : answer.views)
      views.push_back({{"view", scene.views[v].name}, {"pixels", pixels}});
    PrintJsonLine(nlohmann::json({{"instance", answer.instance},
                                  {"gaussians", answer.gaussians},
                                  {"views", views},
                                  {"query_ms", click_ms},
                                  {"index_ms", build_ms}})
                      .dump());
  }
  return absl::OkStatus();
}

}  // namespace

void AddQueryCommand(CLI::App& app, Action* action) {
  auto args = std::make_shared<QueryArgs>();
  CLI::App* cmd = app.add_subcommand(
      "query", "Click query: the instance under a pixel (or nearest a 3D point) and its masks");
  cmd->add_option("--scene", args->scene, "Scene directory")->required();
  cmd->add_option("--result", args->result, "Result directory (instascene run/train/decompose)")
      ->required();
  cmd->add_option("--view", args->view, "View name or index of the click");
  cmd->add_option("--pixel", args->pixel, "Clicked pixel X,Y");
  cmd->add_option("--point", args->point, "Or a 3D point X,Y,Z (world)");
  cmd->add_option("--ray", args->ray, "Or a ray OX,OY,OZ,DX,DY,DZ (origin and direction, world)");
  cmd->add_option("--max-distance", args->max_distance,
                  "3D point query: nearest-Gaussian radius (scene units)");
  cmd->add_option("--out", args->out, "Write the instance's mask in every view as PNGs here");
  cmd->add_flag("--json", args->json, "Print the answer as one JSON line");
  cmd->callback([args, action] { *action = [args] { return RunQuery(*args); }; });
}

}  // namespace instascene::cli
