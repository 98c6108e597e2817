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

void AddQueryCommand(CLI::App& app, Action* action) {
  struct Args {
    std::string scene, result, view = "0", pixel, point, ray, out;
    float max_distance = 0.02f;
    bool json = false;
  };
  auto args = std::make_shared<Args>();
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
  cmd->callback([args, action] {
    *action = [args]() -> absl::Status {
      if (args->pixel.empty() + args->point.empty() + args->ray.empty() != 2) {
        return absl::InvalidArgumentError("give exactly one of --pixel, --point or --ray");
      }
      ASSIGN_OR_RETURN(Scene scene, ReadScene(args->scene));
      ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSceneGaussians(scene));
      ASSIGN_OR_RETURN(SegmentationResult result, ReadResult(args->result, cloud.size()));
      Stopwatch build;
      ASSIGN_OR_RETURN(std::unique_ptr<objects::QueryIndex> index,
                       objects::QueryIndex::Build(scene, cloud, result));
      const double build_ms = build.ElapsedMs();
      Stopwatch click;
      objects::QueryAnswer answer;
      if (!args->pixel.empty()) {
        ASSIGN_OR_RETURN(std::vector<double> values,
                         ParseNumbers(args->pixel, 2, "--pixel", "X,Y"));
        ASSIGN_OR_RETURN(int view, ResolveView(scene, args->view));
        ASSIGN_OR_RETURN(
            answer, index->Click(view, static_cast<int>(values[0]), static_cast<int>(values[1])));
      } else if (!args->ray.empty()) {
        ASSIGN_OR_RETURN(std::vector<double> values,
                         ParseNumbers(args->ray, 6, "--ray", "OX,OY,OZ,DX,DY,DZ"));
        ASSIGN_OR_RETURN(
            answer, index->Ray(Eigen::Vector3d(values[0], values[1], values[2]).cast<float>(),
                               Eigen::Vector3d(values[3], values[4], values[5]).cast<float>()));
      } else {
        ASSIGN_OR_RETURN(std::vector<double> values,
                         ParseNumbers(args->point, 3, "--point", "X,Y,Z"));
        ASSIGN_OR_RETURN(
            answer, index->Point(Eigen::Vector3d(values[0], values[1], values[2]).cast<float>(),
                                 args->max_distance));
      }
      const double click_ms = click.ElapsedMs();
      if (!args->out.empty() && answer.instance != 0) {
        std::filesystem::create_directories(args->out);
        for (const auto& [v, pixels] : answer.views) {
          std::vector<uint8_t> mask = index->Mask(answer.instance, v);
          LabelMap png{scene.views[v].camera.width, scene.views[v].camera.height,
                       std::vector<uint16_t>(mask.begin(), mask.end())};
          RETURN_IF_ERROR(WriteLabelMap(
              (std::filesystem::path(args->out) / (scene.views[v].name + ".png")).string(), png));
        }
      }
      std::printf(
          "instance %u: %zu Gaussians, visible in %zu views (index built in %.0f ms, query %.3f "
          "ms)\n",
          answer.instance, answer.gaussians, answer.views.size(), build_ms, click_ms);
      if (args->json) {
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
    };
  });
}

}  // namespace instascene::cli
