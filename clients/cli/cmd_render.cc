// `instascene render` and `instascene info`: render a scene view (or a bare .ply from an orbit
// camera) to PNG, and describe a scene or a .ply.
#include <cmath>
#include <cstdio>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "clients/cli/cli.h"
#include "common/core/status.h"
#include "common/eval/result.h"
#include "common/raster/label_render.h"
#include "common/raster/rasterizer.h"
#include "common/raster/visualize.h"
#include "common/scene/image_io.h"
#include "common/scene/scene.h"
#include "common/splat/gaussian_ply.h"
#include "common/splat/splat_formats.h"

namespace instascene::cli {
namespace {

// Parses "x", "-y", ... into a unit axis.
absl::StatusOr<Eigen::Vector3d> ParseAxis(const std::string& text) {
  const double sign = !text.empty() && text[0] == '-' ? -1.0 : 1.0;
  const std::string axis = text.substr(!text.empty() && (text[0] == '-' || text[0] == '+') ? 1 : 0);
  if (axis == "x") return Eigen::Vector3d(sign, 0, 0);
  if (axis == "y") return Eigen::Vector3d(0, sign, 0);
  if (axis == "z") return Eigen::Vector3d(0, 0, sign);
  return absl::InvalidArgumentError(
      absl::StrCat("--up must be one of x, y, z, -x, -y, -z; got '", text, "'"));
}

}  // namespace

// Shared by render and the demo: converts a render result to the requested RGB visualisation.
absl::StatusOr<std::vector<float>> Visualize(const RenderResult& r, const std::string& mode,
                                             int feature_dim) {
  if (mode == "color") return r.color;
  if (mode == "depth") return ColorizeDepth(r.median_depth, r.alpha);
  if (mode == "normal") return NormalsToRgb(r.normal);
  if (mode == "alpha") return GrayToRgb(r.alpha);
  if (mode == "features") return FeaturesToRgb(r.features, feature_dim);
  return absl::InvalidArgumentError(
      absl::StrCat("unknown --mode '", mode, "' (color, depth, normal, alpha, labels, features)"));
}

namespace {

struct RenderArgs {
  std::string scene, view = "0", ply, out, mode = "color", up = "-y", feature_prefix = "segfeat_",
                     result;
  std::string orbit = "0,20";
  int width = 800, height = 600, threads = 0;
  double fov = 50.0, distance = 2.2;
  bool surfels = false, json = false;
  std::vector<float> background = {0, 0, 0};
};

// A bare splat file's orbit camera around its robust centre.
absl::StatusOr<PinholeCamera> OrbitCameraFor(const GaussianCloud& cloud, const RenderArgs& a) {
  std::vector<std::string> parts = absl::StrSplit(a.orbit, ',');
  double az = 0, el = 0;
  if (parts.size() != 2 || !absl::SimpleAtod(parts[0], &az) || !absl::SimpleAtod(parts[1], &el)) {
    return absl::InvalidArgumentError("--orbit must be AZIMUTH,ELEVATION in degrees");
  }
  ASSIGN_OR_RETURN(Eigen::Vector3d up, ParseAxis(a.up));
  const Eigen::AlignedBox3f box = RobustBounds(cloud);
  const Eigen::Vector3d center = box.center().cast<double>();
  const double radius = std::max(0.5 * static_cast<double>(box.diagonal().norm()), 1e-3);
  return OrbitCamera(center, up, a.distance * radius, az, el, a.width, a.height, a.fov);
}

// The cloud and the camera: a scene's view, or a splat file from an orbit camera.
absl::Status LoadRenderInput(const RenderArgs& a, GaussianCloud* cloud, PinholeCamera* camera) {
  if (a.scene.empty() == a.ply.empty())
    return absl::InvalidArgumentError("give exactly one of --scene or --ply");
  if (!a.scene.empty()) {
    ASSIGN_OR_RETURN(Scene scene, ReadScene(a.scene));
    ASSIGN_OR_RETURN(int view, ResolveView(scene, a.view));
    ASSIGN_OR_RETURN(*cloud, ReadSceneGaussians(scene));
    *camera = scene.views[view].camera;
  } else {
    ASSIGN_OR_RETURN(*cloud, ReadSplatFile(a.ply));
    if (cloud->size() == 0)
      return absl::InvalidArgumentError(absl::StrCat(a.ply, ": no Gaussians"));
    ASSIGN_OR_RETURN(*camera, OrbitCameraFor(*cloud, a));
  }
  if (a.surfels) *cloud = ToSurfels(*cloud);
  return absl::OkStatus();
}

absl::Status RunRender(const RenderArgs& a) {
  GaussianCloud cloud;
  PinholeCamera camera;
  RETURN_IF_ERROR(LoadRenderInput(a, &cloud, &camera));
  RenderOptions options;
  options.depth = a.mode == "depth";
  options.normal = a.mode == "normal";
  for (int c = 0; c < 3; ++c) options.background[c] = a.background[c];
  options.num_threads = a.threads;
  std::vector<float> features;
  int dim = 0;
  if (a.mode == "features") {
    ASSIGN_OR_RETURN(features, cloud.GatherExtraGroup(a.feature_prefix, &dim));
    if (dim == 0)
      return absl::InvalidArgumentError(
          absl::StrCat("the cloud has no '", a.feature_prefix, "*' channels"));
    options.features = features.data();
    options.feature_dim = dim;
  }
  std::vector<float> rgb;
  RenderResult r;
  if (a.mode == "labels") {
    if (a.result.empty()) return absl::InvalidArgumentError("--mode labels needs --result DIR");
    ASSIGN_OR_RETURN(SegmentationResult result, ReadResult(a.result, cloud.size()));
    options.trace.enabled = true;
    ASSIGN_OR_RETURN(r, Render(cloud, camera, options));
    rgb = LabelsToRgb(LabelMapFromTrace(r, result.labels));
  } else {
    ASSIGN_OR_RETURN(r, Render(cloud, camera, options));
    ASSIGN_OR_RETURN(rgb, Visualize(r, a.mode, dim));
  }
  RETURN_IF_ERROR(WriteImage(a.out, Image{r.width, r.height, 3, std::move(rgb)}));
  std::fprintf(stderr, "render: %s (%dx%d, %zu Gaussians, %s) in %.1f ms\n", a.out.c_str(), r.width,
               r.height, cloud.size(), a.mode.c_str(), r.stats.total_ms);
  if (a.json) {
    PrintJsonLine(nlohmann::json({{"out", a.out},
                                  {"width", r.width},
                                  {"height", r.height},
                                  {"gaussians", cloud.size()},
                                  {"ms", r.stats.total_ms}})
                      .dump());
  }
  return absl::OkStatus();
}

}  // namespace

void AddRenderCommand(CLI::App& app, Action* action) {
  auto args = std::make_shared<RenderArgs>();
  CLI::App* cmd = app.add_subcommand(
      "render", "Render a scene view, or a bare .ply from an orbit camera, to PNG");
  auto* scene_opt = cmd->add_option("--scene", args->scene, "Scene directory");
  cmd->add_option("--view", args->view, "View name or index (with --scene)");
  auto* ply_opt = cmd->add_option("--ply", args->ply,
                                  "Render this splat file (.ply, compressed .ply, .splat, .spz) "
                                  "without a scene (orbit camera)");
  scene_opt->excludes(ply_opt);
  cmd->add_option("--out", args->out, "Output PNG")->required();
  cmd->add_option("--mode", args->mode,
                  "color, depth (median), normal, alpha, labels (of --result) or features (PCA of "
                  "--feature-prefix channels)");
  cmd->add_option("--result", args->result,
                  "--mode labels: a result directory (instance labels per Gaussian)");
  cmd->add_option("--orbit", args->orbit,
                  "Bare .ply: azimuth,elevation in degrees around the robust centre");
  cmd->add_option("--distance", args->distance,
                  "Bare .ply: camera distance in units of the robust radius");
  cmd->add_option("--up", args->up, "Bare .ply: world up axis (3DGS captures are usually -y)");
  cmd->add_option("--width", args->width, "Bare .ply: image width, px");
  cmd->add_option("--height", args->height, "Bare .ply: image height, px");
  cmd->add_option("--fov", args->fov, "Bare .ply: horizontal field of view, degrees");
  cmd->add_option("--background", args->background, "Background RGB in [0,1]")->expected(3);
  cmd->add_option("--feature-prefix", args->feature_prefix,
                  "Extra channels rendered by --mode features");
  cmd->add_flag("--surfels", args->surfels,
                "Render a 3DGS cloud as 2DGS surfels (drop the smallest axis)");
  cmd->add_option("--threads", args->threads, "Threads (0 = all cores)");
  cmd->add_flag("--json", args->json, "Print a JSON summary as the last stdout line");
  cmd->callback([args, action] { *action = [args] { return RunRender(*args); }; });
}

namespace {

struct InfoArgs {
  std::string scene, ply;
  bool json = false;
};

// The scene's views, images, masks, size and ground truth; the cloud's size, SH and extras.
absl::StatusOr<nlohmann::json> Describe(const InfoArgs& a) {
  if (a.scene.empty() == a.ply.empty())
    return absl::InvalidArgumentError("give exactly one of --scene or --ply");
  nlohmann::json j;
  GaussianCloud cloud;
  if (!a.scene.empty()) {
    ASSIGN_OR_RETURN(Scene scene, ReadScene(a.scene));
    ASSIGN_OR_RETURN(cloud, ReadSceneGaussians(scene));
    int masks = 0, images = 0;
    for (const SceneView& v : scene.views) {
      masks += !v.mask.empty();
      images += !v.image.empty();
    }
    j["scene"] = a.scene;
    j["views"] = scene.views.size();
    j["images"] = images;
    j["masks"] = masks;
    if (!scene.views.empty()) {
      j["width"] = scene.views[0].camera.width;
      j["height"] = scene.views[0].camera.height;
    }
    j["ground_truth"] = scene.metadata.contains("gt");
  } else {
    ASSIGN_OR_RETURN(cloud, ReadSplatFile(a.ply));
    j["ply"] = a.ply;
  }
  j["gaussians"] = cloud.size();
  j["scales"] = cloud.num_scales;
  j["sh_degree"] = cloud.sh_degree;
  std::vector<std::string> extras;
  for (const ExtraChannel& e : cloud.extras) extras.push_back(e.name);
  j["extra_channels"] = extras;
  Eigen::AlignedBox3f box;
  for (size_t i = 0; i < cloud.size(); ++i) box.extend(Eigen::Vector3f(&cloud.positions[3 * i]));
  if (!box.isEmpty()) {
    j["bounds_min"] = {box.min().x(), box.min().y(), box.min().z()};
    j["bounds_max"] = {box.max().x(), box.max().y(), box.max().z()};
  }
  return j;
}

}  // namespace

void AddInfoCommand(CLI::App& app, Action* action) {
  auto args = std::make_shared<InfoArgs>();
  CLI::App* cmd = app.add_subcommand("info", "Describe a scene directory or a .ply");
  cmd->add_option("--scene", args->scene, "Scene directory");
  cmd->add_option("--ply", args->ply, "A splat file: Inria/2DGS or compressed .ply, .splat, .spz");
  cmd->add_flag("--json", args->json, "Print the description as one JSON line");
  cmd->callback([args, action] {
    *action = [args]() -> absl::Status {
      ASSIGN_OR_RETURN(const nlohmann::json j, Describe(*args));
      if (args->json) {
        PrintJsonLine(j.dump());
      } else {
        std::printf("%s\n", j.dump(2).c_str());
      }
      return absl::OkStatus();
    };
  });
}

}  // namespace instascene::cli
