#include "services/pipeline/memory.h"

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/scene/scene.h"
#include "common/splat/splat_formats.h"

namespace instascene::pipeline {

absl::StatusOr<int64_t> ReadGaussianCount(const std::string& ply_path) {
  std::ifstream in(ply_path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot open the splat ", ply_path));
  std::string head(1 << 20, '\0');  // any sane header fits in the first MiB
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(in.gcount()));
  std::error_code ec;
  const auto size = std::filesystem::file_size(ply_path, ec);
  if (ec) return absl::NotFoundError(absl::StrCat("cannot stat the splat ", ply_path));
  return SplatCount(head, static_cast<int64_t>(size), ply_path);
}

absl::StatusOr<SceneFootprint> ReadSceneFootprint(const std::string& scene_dir) {
  ASSIGN_OR_RETURN(Scene scene, ReadScene(scene_dir));
  SceneFootprint f;
  f.views = static_cast<int64_t>(scene.views.size());
  for (const SceneView& v : scene.views) {
    const int64_t pixels = int64_t{v.camera.width} * v.camera.height;
    f.total_pixels += pixels;
    f.max_view_pixels = std::max(f.max_view_pixels, pixels);
  }
  ASSIGN_OR_RETURN(f.gaussians, ReadGaussianCount(scene.Path(scene.gaussians)));
  return f;
}

int64_t PhysicalMemoryBytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  return pages > 0 && page > 0 ? int64_t{pages} * page : 0;
}

}  // namespace instascene::pipeline
