#include "common/scene/scene.h"

#include <cmath>

#include <charconv>
#include <filesystem>
#include <set>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/splat/gaussian_ply.h"
#include "common/splat/ply.h"
#include "common/splat/splat_formats.h"

namespace instascene {
namespace {

using nlohmann::json;

// A relative path that stays inside the scene: no absolute paths, no "..", no empty components.
bool IsSafeRelativePath(const std::string& path) {
  if (path.empty() || path.front() == '/' || path.find('\\') != std::string::npos) return false;
  for (const auto& part : std::filesystem::path(path)) {
    if (part == ".." || part == "." || part.empty()) return false;
  }
  return true;
}

constexpr int64_t kMaxViewSide = 16384;  // pixels per image side

absl::StatusOr<SceneView> ParseView(const json& j, size_t index) {
  auto fail = [&](const std::string& what) {
    return absl::InvalidArgumentError(absl::StrCat("views[", index, "]: ", what));
  };
  if (!j.is_object()) return fail("not an object");
  SceneView view;
  try {
    view.name = j.at("name").get<std::string>();
    view.image = j.value("image", std::string());
    view.mask = j.value("mask", std::string());
    // Sizes are read as what they are: 4294967392 must not wrap to 96.
    for (const char* key : {"width", "height"}) {
      const json& v = j.at(key);
      if (!v.is_number_integer() || v.get<int64_t>() < 1 || v.get<int64_t>() > kMaxViewSide ||
          (v.is_number_unsigned() && v.get<uint64_t>() > static_cast<uint64_t>(kMaxViewSide)))
        return fail(
            absl::StrCat(key, " ", v.dump(), " is not an integer in [1, ", kMaxViewSide, "]"));
    }
    view.camera.width = j.at("width").get<int>();
    view.camera.height = j.at("height").get<int>();
    view.camera.fx = j.at("fx").get<double>();
    view.camera.fy = j.at("fy").get<double>();
    view.camera.cx = j.at("cx").get<double>();
    view.camera.cy = j.at("cy").get<double>();
    const json& m = j.at("camera_from_world");
    if (!m.is_array() || m.size() != 3)
      return fail("camera_from_world must be 3 rows of 4 numbers");
    Eigen::Matrix<double, 3, 4> matrix;
    for (int r = 0; r < 3; ++r) {
      if (!m[r].is_array() || m[r].size() != 4)
        return fail("camera_from_world must be 3 rows of 4 numbers");
      for (int c = 0; c < 4; ++c) matrix(r, c) = m[r][c].get<double>();
    }
    absl::StatusOr<Rigid3d> pose = RigidFromMatrix(matrix);
    if (!pose.ok()) return fail(std::string(pose.status().message()));
    view.camera.camera_from_world = *pose;
  } catch (const json::exception& e) {
    return fail(absl::StrCat("bad or missing field: ", e.what()));
  }
  if (view.name.empty() || view.name.size() > 200 || view.name.find('/') != std::string::npos) {
    return fail(absl::StrCat("invalid view name '", view.name, "'"));
  }
  for (const std::string* path : {&view.image, &view.mask}) {
    if (!path->empty() && !IsSafeRelativePath(*path))
      return fail(absl::StrCat("unsafe path '", *path, "'"));
  }
  if (absl::Status s = view.camera.Validate(); !s.ok()) return fail(std::string(s.message()));
  return view;
}

}  // namespace

std::string Scene::Path(const std::string& relative) const {
  return (std::filesystem::path(directory) / relative).string();
}

int Scene::FindView(absl::string_view name) const {
  for (size_t i = 0; i < views.size(); ++i) {
    if (views[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

absl::StatusOr<Scene> ParseSceneJson(absl::string_view text, absl::string_view source) {
  auto fail = [&](const std::string& what) {
    return absl::InvalidArgumentError(absl::StrCat(source, ": ", what));
  };
  json root = json::parse(text.begin(), text.end(), nullptr, /*allow_exceptions=*/false);
  if (root.is_discarded()) return fail("not valid JSON");
  if (!root.is_object()) return fail("top level must be an object");
  // (a "format" of another type must not throw: found by scene_json_fuzz)
  if (!root.contains("format") || !root["format"].is_string() ||
      root["format"].get<std::string>() != kSceneFormat) {
    return fail(absl::StrCat("\"format\" must be \"", kSceneFormat, "\""));
  }
  Scene scene;
  if (root.contains("gaussians")) {
    if (!root["gaussians"].is_string()) return fail("\"gaussians\" must be a string");
    scene.gaussians = root["gaussians"].get<std::string>();
  }
  if (!IsSafeRelativePath(scene.gaussians))
    return fail(absl::StrCat("unsafe path '", scene.gaussians, "'"));
  if (root.contains("meters_per_unit")) {
    const json& m = root["meters_per_unit"];
    if (!m.is_number() || !(m.get<double>() > 0) || !std::isfinite(m.get<double>()) ||
        m.get<double>() > 1e6)
      return fail("\"meters_per_unit\" must be a positive number (metres per scene unit)");
    scene.meters_per_unit = m.get<double>();
  }
  if (!root.contains("views") || !root["views"].is_array())
    return fail("\"views\" must be an array");
  std::set<std::string> names;
  for (size_t i = 0; i < root["views"].size(); ++i) {
    absl::StatusOr<SceneView> view = ParseView(root["views"][i], i);
    if (!view.ok()) return Annotate(view.status(), source);
    if (!names.insert(view->name).second)
      return fail(absl::StrCat("duplicate view name '", view->name, "'"));
    scene.views.push_back(*std::move(view));
  }
  for (auto it = root.begin(); it != root.end(); ++it) {
    if (it.key() != "format" && it.key() != "gaussians" && it.key() != "views" &&
        it.key() != "meters_per_unit")
      scene.metadata[it.key()] = it.value();
  }
  return scene;
}

std::string SceneToJson(const Scene& scene) {
  json root = scene.metadata;
  root["format"] = kSceneFormat;
  root["gaussians"] = scene.gaussians;
  if (scene.meters_per_unit) root["meters_per_unit"] = *scene.meters_per_unit;
  json views = json::array();
  for (const SceneView& v : scene.views) {
    const PinholeCamera& c = v.camera;
    json m = json::array();
    const Eigen::Matrix<double, 3, 4> matrix = c.camera_from_world.ToMatrix();
    for (int r = 0; r < 3; ++r)
      m.push_back({matrix(r, 0), matrix(r, 1), matrix(r, 2), matrix(r, 3)});
    views.push_back({{"name", v.name},
                     {"image", v.image},
                     {"mask", v.mask},
                     {"width", c.width},
                     {"height", c.height},
                     {"fx", c.fx},
                     {"fy", c.fy},
                     {"cx", c.cx},
                     {"cy", c.cy},
                     {"camera_from_world", m}});
  }
  root["views"] = views;
  return root.dump(1);
}

absl::StatusOr<Scene> ReadScene(const std::string& directory) {
  const std::string path = (std::filesystem::path(directory) / "scene.json").string();
  ASSIGN_OR_RETURN(std::string text, ReadFileBounded(path, size_t{64} << 20));
  ASSIGN_OR_RETURN(Scene scene, ParseSceneJson(text, path));
  scene.directory = directory;
  return scene;
}

absl::Status WriteScene(const Scene& scene) {
  std::error_code ec;
  std::filesystem::create_directories(scene.directory, ec);
  if (ec)
    return absl::UnavailableError(absl::StrCat(scene.directory, ": cannot create: ", ec.message()));
  return WriteFileAtomically(scene.Path("scene.json"), SceneToJson(scene));
}

absl::StatusOr<int> ResolveView(const Scene& scene, absl::string_view name_or_index) {
  const int by_name = scene.FindView(name_or_index);
  if (by_name >= 0) return by_name;
  int index = -1;
  auto r =
      std::from_chars(name_or_index.data(), name_or_index.data() + name_or_index.size(), index);
  if (r.ec == std::errc() && r.ptr == name_or_index.data() + name_or_index.size() && index >= 0 &&
      index < static_cast<int>(scene.views.size())) {
    return index;
  }
  return absl::NotFoundError(absl::StrCat("no view named '", name_or_index,
                                          "' (and not an index below ", scene.views.size(), ")"));
}

absl::StatusOr<GaussianCloud> ReadSceneGaussians(const Scene& scene) {
  return ReadSplatFile(scene.Path(scene.gaussians));  // any splat format users' tools export
}

}  // namespace instascene
