#include "common/synth/scene_writer.h"

#include <cstdio>
#include <filesystem>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "common/core/status.h"
#include "common/eval/result.h"
#include "common/mesh/mesh_ply.h"
#include "common/raster/label_render.h"
#include "common/raster/rasterizer.h"
#include "common/scene/image_io.h"
#include "common/scene/scene.h"
#include "common/splat/gaussian_ply.h"
#include "common/splat/ply.h"

#include <algorithm>
#include <nlohmann/json.hpp>

namespace instascene {
namespace {

nlohmann::json ObjectJson(const SynthObject& o, const GaussianCloud& cloud) {
  nlohmann::json pose = nlohmann::json::array();
  const Eigen::Matrix<double, 3, 4> m = o.world_from_object.ToMatrix();
  for (int r = 0; r < 3; ++r) pose.push_back({m(r, 0), m(r, 1), m(r, 2), m(r, 3)});
  Eigen::AlignedBox3f box = o.mesh.Bounds();
  if (o.mesh.vertices.empty()) {  // no mesh (real captures): the bounds of its Gaussians
    for (size_t i = o.first_gaussian; i < o.first_gaussian + o.num_gaussians; ++i)
      box.extend(Eigen::Vector3f(&cloud.positions[3 * i]));
  }
  return {{"id", o.id},
          {"name", o.name},
          {"shape", ShapeKindName(o.shape.kind)},
          {"size", {o.shape.size.x(), o.shape.size.y(), o.shape.size.z()}},
          {"world_from_object", pose},
          {"scale", o.scale},
          {"duplicate_group", o.duplicate_group},
          {"first_gaussian", o.first_gaussian},
          {"num_gaussians", o.num_gaussians},
          {"color", {o.appearance.color_a.x(), o.appearance.color_a.y(), o.appearance.color_a.z()}},
          {"bounds_min", {box.min().x(), box.min().y(), box.min().z()}},
          {"bounds_max", {box.max().x(), box.max().y(), box.max().z()}},
          {"mesh", o.mesh.triangles.empty()
                       ? nlohmann::json(nullptr)
                       : nlohmann::json(absl::StrCat("gt/meshes/", o.id, ".ply"))}};
}

}  // namespace

LabelMap GroundTruthInstanceMap(const RenderResult& traced,
                                const std::vector<uint32_t>& instance_ids) {
  const std::vector<uint32_t> map = LabelMapFromTrace(traced, instance_ids, 0.5f);
  return LabelMap{traced.width, traced.height, std::vector<uint16_t>(map.begin(), map.end())};
}

namespace {
namespace fs = std::filesystem;

// gt/: per-Gaussian ids (gt/ is itself a result directory, result.json + labels.ply:
// `instascene eval --result <scene>/gt` scores the ground truth, 1.0 by construction), the
// objects, their meshes and complete surfels, the stuff mesh.
absl::Status WriteGroundTruth(const ClutterScene& scene, const Scene& out,
                              const SegmentationResult& gt_result) {
  const std::string& directory = out.directory;
  std::error_code ec;
  RETURN_IF_ERROR(WriteResult(out.Path("gt"), gt_result, scene.cloud));
  nlohmann::json objects = nlohmann::json::array();
  for (size_t k = 0; k < scene.objects.size(); ++k) {
    const SynthObject& o = scene.objects[k];
    objects.push_back(ObjectJson(o, scene.cloud));
    if (k < scene.complete_surfels.size()) {
      fs::create_directories(fs::path(directory) / "gt/complete", ec);
      if (ec)
        return absl::UnavailableError(absl::StrCat(directory, "/gt/complete: ", ec.message()));
      const std::string file = absl::StrCat("gt/complete/", o.id, ".ply");
      RETURN_IF_ERROR(WriteGaussianPly(out.Path(file), scene.complete_surfels[k]));
      objects.back()["complete_surfels"] = file;
    }
    if (!o.mesh.triangles.empty()) {  // real-capture composites have no complete geometry
      RETURN_IF_ERROR(WriteFileAtomically(out.Path(absl::StrCat("gt/meshes/", o.id, ".ply")),
                                          EncodeMeshPly(o.mesh)));
    }
  }
  RETURN_IF_ERROR(WriteFileAtomically(out.Path("gt/objects.json"), objects.dump(1)));
  if (!scene.stuff_mesh.triangles.empty()) {
    RETURN_IF_ERROR(WriteMeshPly(out.Path("gt/meshes/stuff.ply"), scene.stuff_mesh));
  }
  return absl::OkStatus();
}

nlohmann::json GroundTruthMetadata(const ClutterScene& scene, const SceneWriteOptions& options) {
  return {
      {"format", "instascene.gt/1"},
      {"objects", "gt/objects.json"},
      {"gaussian_instances", "gt/labels.ply"},
      {"masks", "gt/masks"},
      {"meshes", "gt/meshes"},
      {"stuff_mesh", scene.stuff_mesh.triangles.empty() ? nlohmann::json(nullptr)
                                                        : nlohmann::json("gt/meshes/stuff.ply")},
      {"unseen_surfels", scene.complete_surfels.empty() ? "kept" : "dropped"},
      {"mask_noise", options.mask_noise},
      {"seed", options.seed}};
}

// View v: its image, its ground-truth instance map and the simulated segmenter's masks.
absl::StatusOr<SceneView> WriteView(const ClutterScene& scene, const Scene& out, int v,
                                    const std::vector<uint32_t>& gt_labels,
                                    const MaskNoiseOptions& noise,
                                    const SceneWriteOptions& options) {
  RenderOptions render;
  render.num_threads = options.num_threads;
  render.trace.enabled = true;  // every contribution: the ground-truth masks sum weights
  SceneView view;
  view.name = absl::StrFormat("%04d", v);
  view.image = absl::StrCat("images/", view.name, ".png");
  view.camera = scene.cameras[v];
  view.mask = absl::StrCat("masks/", view.name, ".png");
  ASSIGN_OR_RETURN(RenderResult r, Render(scene.cloud, view.camera, render));
  const LabelMap gt = GroundTruthInstanceMap(r, gt_labels);
  RETURN_IF_ERROR(WriteLabelMap(out.Path(absl::StrCat("gt/masks/", view.name, ".png")), gt));
  RETURN_IF_ERROR(
      WriteLabelMap(out.Path(view.mask), SimulateSegmenter(gt, noise, options.seed * 1000003 + v)));
  Image image{r.width, r.height, 3, std::move(r.color)};
  RETURN_IF_ERROR(WriteImage(out.Path(view.image), image));
  return view;
}

}  // namespace

absl::Status WriteClutterScene(const ClutterScene& scene, const std::string& directory,
                               const SceneWriteOptions& options) {
  std::error_code ec;
  fs::create_directories(fs::path(directory) / "images", ec);
  if (ec) return absl::UnavailableError(absl::StrCat(directory, ": cannot create: ", ec.message()));
  Scene out;
  out.directory = directory;
  ASSIGN_OR_RETURN(MaskNoiseOptions noise, MaskNoiseOptions::Level(options.mask_noise));
  for (const char* sub : {"masks", "gt/masks", "gt/meshes"}) {
    fs::create_directories(fs::path(directory) / sub, ec);
    if (ec)
      return absl::UnavailableError(
          absl::StrCat(directory, "/", sub, ": cannot create: ", ec.message()));
  }
  RETURN_IF_ERROR(WriteGaussianPly(out.Path(out.gaussians), scene.cloud));
  SegmentationResult gt_result;
  gt_result.stage = "ground-truth";
  gt_result.labels.assign(scene.instance_ids.begin(), scene.instance_ids.end());
  RETURN_IF_ERROR(WriteGroundTruth(scene, out, gt_result));
  out.meters_per_unit = 1.0;  // the synthetic world is in metres (cluttered_scene.h)
  out.metadata["gt"] = GroundTruthMetadata(scene, options);
  const int total = static_cast<int>(scene.cameras.size());
  for (int v = 0; v < total; ++v) {
    ASSIGN_OR_RETURN(SceneView view, WriteView(scene, out, v, gt_result.labels, noise, options));
    out.views.push_back(std::move(view));
    if (options.progress) options.progress(v + 1, total);
  }
  return WriteScene(out);
}

}  // namespace instascene
