// `instascene import`: build a scene directory from a COLMAP model or a transforms.json, a trained
// .ply and optional masks.
#include <cstdio>
#include <filesystem>

#include "absl/strings/str_cat.h"
#include "clients/cli/cli.h"
#include "common/core/status.h"
#include "common/scene/image_io.h"
#include "common/scene/importers.h"
#include "common/splat/gaussian_ply.h"
#include "common/splat/splat_formats.h"

namespace instascene::cli {

namespace {
namespace fs = std::filesystem;

struct ImportArgs {
  std::string colmap, transforms, ply, images, masks, out;
  bool assume_undistorted = false;
  double meters_per_unit = 0;  // 0 = unknown (not written)
};

// The cameras, and the folder their images are in.
absl::StatusOr<ImportedCameras> ImportCameras(const ImportArgs& a, std::string* image_dir) {
  if (a.colmap.empty() == a.transforms.empty())
    return absl::InvalidArgumentError("give exactly one of --colmap or --transforms");
  ImportOptions options;
  options.assume_undistorted = a.assume_undistorted;
  *image_dir = a.images;
  if (!a.colmap.empty()) {
    if (image_dir->empty())
      *image_dir = (fs::path(a.colmap) / ".." / ".." / "images").lexically_normal().string();
    return ImportColmapModel(a.colmap, options);
  }
  if (image_dir->empty()) *image_dir = fs::path(a.transforms).parent_path().string();
  return ImportTransformsJson(a.transforms, options);
}

// Copies a view's image (and its mask, when the mask folder has one) into the scene; returns
// whether it had a mask.
absl::StatusOr<bool> CopyViewFiles(const ImportArgs& a, const std::string& image_dir,
                                   const Scene& scene, SceneView& view) {
  std::error_code ec;
  const fs::path src = fs::path(image_dir) / view.image;
  if (!fs::exists(src))
    return absl::NotFoundError(
        absl::StrCat(src.string(), ": image of view '", view.name, "' not found"));
  const std::string rel = absl::StrCat("images/", view.name, src.extension().string());
  fs::copy_file(src, scene.Path(rel), fs::copy_options::overwrite_existing, ec);
  if (ec)
    return absl::UnavailableError(absl::StrCat(scene.Path(rel), ": copy failed: ", ec.message()));
  view.image = rel;
  if (a.masks.empty()) return false;
  const fs::path mask = fs::path(a.masks) / (view.name + ".png");
  if (!fs::exists(mask)) return false;
  fs::create_directories(fs::path(a.out) / "masks", ec);
  view.mask = absl::StrCat("masks/", view.name, ".png");
  fs::copy_file(mask, scene.Path(view.mask), fs::copy_options::overwrite_existing, ec);
  if (ec) return absl::UnavailableError(absl::StrCat(scene.Path(view.mask), ": copy failed"));
  return true;
}

absl::Status RunImport(const ImportArgs& a) {
  std::string image_dir;
  ASSIGN_OR_RETURN(ImportedCameras cams, ImportCameras(a, &image_dir));
  for (const std::string& w : cams.warnings)
    std::fprintf(stderr, "import: warning: %s\n", w.c_str());
  ASSIGN_OR_RETURN(GaussianCloud cloud, ReadSplatFile(a.ply));  // validates before copying
  Scene scene;
  scene.directory = a.out;
  if (a.meters_per_unit > 0) scene.meters_per_unit = a.meters_per_unit;
  std::error_code ec;
  fs::create_directories(fs::path(a.out) / "images", ec);
  if (ec) return absl::UnavailableError(absl::StrCat(a.out, ": cannot create: ", ec.message()));
  RETURN_IF_ERROR(WriteGaussianPly(scene.Path(scene.gaussians), cloud));
  int masks = 0;
  for (SceneView& view : cams.views) {
    ASSIGN_OR_RETURN(const bool has_mask, CopyViewFiles(a, image_dir, scene, view));
    masks += has_mask;
  }
  scene.views = std::move(cams.views);
  RETURN_IF_ERROR(WriteScene(scene));
  for (int v = 0; v < static_cast<int>(scene.views.size()); ++v) {
    RETURN_IF_ERROR(ReadViewImage(scene, v).status());  // sizes must match the cameras
  }
  std::fprintf(stderr, "import: wrote %s: %zu views, %d masks, %zu Gaussians\n", a.out.c_str(),
               scene.views.size(), masks, cloud.size());
  return absl::OkStatus();
}

}  // namespace

void AddImportCommand(CLI::App& app, Action* action) {
  auto args = std::make_shared<ImportArgs>();
  CLI::App* cmd = app.add_subcommand(
      "import", "Build a scene directory from COLMAP or transforms.json cameras and a .ply");
  auto* colmap = cmd->add_option("--colmap", args->colmap,
                                 "COLMAP model folder (cameras/images .bin or .txt)");
  auto* transforms =
      cmd->add_option("--transforms", args->transforms, "instant-ngp / nerfstudio transforms.json");
  colmap->excludes(transforms);
  cmd->add_option("--ply", args->ply,
                  "The trained splat: Inria/2DGS or compressed .ply, .splat or .spz (converted to "
                  "the internal PLY)")
      ->required();
  cmd->add_option(
      "--images", args->images,
      "Image folder (default: <model>/../../images for COLMAP, the JSON's folder otherwise)");
  cmd->add_option("--masks", args->masks, "Folder of per-view label maps named <image stem>.png");
  cmd->add_option("--out", args->out, "Output scene directory")->required();
  cmd->add_option("--meters-per-unit", args->meters_per_unit,
                  "Metric scale of the reconstruction (metres per scene unit), written to "
                  "scene.json; omit when unknown: objects are then reported unscaled")
      ->check(CLI::PositiveNumber);
  cmd->add_flag("--assume-undistorted", args->assume_undistorted,
                "Accept distorted camera models, ignoring distortion (images already undistorted)");
  cmd->callback([args, action] { *action = [args] { return RunImport(*args); }; });
}

}  // namespace instascene::cli
