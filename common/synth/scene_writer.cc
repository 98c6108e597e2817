#include "common/synth/scene_writer.h"

#include <cstdio>
#include <filesystem>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "common/core/status.h"
#include "common/raster/rasterizer.h"
#include "common/scene/scene.h"
#include "common/splat/gaussian_ply.h"

namespace instascene {

absl::Status WriteClutterScene(const ClutterScene& scene, const std::string& directory,
                               const SceneWriteOptions& options) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(fs::path(directory) / "images", ec);
  if (ec) return absl::UnavailableError(absl::StrCat(directory, ": cannot create: ", ec.message()));
  Scene out;
  out.directory = directory;
  RETURN_IF_ERROR(WriteGaussianPly(out.Path(out.gaussians), scene.cloud));
  RenderOptions render;
  render.num_threads = options.num_threads;
  const int total = static_cast<int>(scene.cameras.size());
  for (int v = 0; v < total; ++v) {
    SceneView view;
    view.name = absl::StrFormat("%04d", v);
    view.image = absl::StrCat("images/", view.name, ".png");
    view.camera = scene.cameras[v];
    ASSIGN_OR_RETURN(RenderResult r, Render(scene.cloud, view.camera, render));
    Image image{r.width, r.height, 3, std::move(r.color)};
    RETURN_IF_ERROR(WriteImage(out.Path(view.image), image));
    out.views.push_back(std::move(view));
    if (options.progress) options.progress(v + 1, total);
  }
  return WriteScene(out);
}

}  // namespace instascene
