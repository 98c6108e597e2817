#include "services/objects/scene_objects.h"

#include <algorithm>
#include <filesystem>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "common/core/status.h"
#include "common/eval/result.h"
#include "common/rpc/status.h"
#include "common/scene/scene.h"
#include "common/splat/splat_formats.h"
#include "common/store/manifest.h"

namespace instascene::objects {
namespace {
namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr int64_t kMaxJsonBytes = 64 << 20;
constexpr int64_t kMaxSplatBytes = int64_t{8} << 30;  // as ReadSplatFile's default

std::string MediaType(const std::string& path) {
  const std::string ext = fs::path(path).extension().string();
  if (ext == ".glb") return "model/gltf-binary";
  if (ext == ".stl") return "model/stl";
  if (ext == ".ply") return "application/x-ply";
  if (ext == ".drc") return "application/x-draco";
  if (ext == ".urdf" || ext == ".xml") return "application/xml";
  if (ext == ".json") return "application/json";
  if (ext == ".png") return "image/png";
  return "application/octet-stream";
}

// A manifest file's bytes, read whole from the store and verified against its digest (a
// damaged blob is DATA_LOSS, never parsed).
absl::StatusOr<std::string> ReadVerifiedFile(store::BlobStore& store,
                                             const store::Manifest& manifest,
                                             const std::string& file, int64_t max_bytes,
                                             const std::string& what) {
  auto it = manifest.files.find(file);
  if (it == manifest.files.end()) return absl::DataLossError(absl::StrCat(what, " has no ", file));
  if (it->second.size_bytes > max_bytes) {
    return absl::ResourceExhaustedError(
        absl::StrCat(what, "/", file, ": ", it->second.size_bytes, " bytes, at most ", max_bytes));
  }
  ASSIGN_OR_RETURN(std::string bytes, store.Read(it->second));
  if (absl::Status s = store::VerifyBlobBytes(it->second, bytes); !s.ok()) {
    return absl::DataLossError(absl::StrCat(what, "/", file, ": ", s.message()));
  }
  return bytes;
}

absl::StatusOr<json> ReadJsonBlob(store::BlobStore& store, const store::Manifest& manifest,
                                  const std::string& file, const std::string& what) {
  ASSIGN_OR_RETURN(const std::string text,
                   ReadVerifiedFile(store, manifest, file, kMaxJsonBytes, what));
  json j = json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object())
    return absl::DataLossError(absl::StrCat(what, "/", file, ": not a JSON object"));
  return j;
}

void SetVector(const Eigen::Vector3d& v, v1::Vector3* out) {
  out->set_x(v.x());
  out->set_y(v.y());
  out->set_z(v.z());
}

absl::StatusOr<Eigen::Vector3d> JsonVector(const json& j, const std::string& what) {
  if (!j.is_array() || j.size() != 3 || !j[0].is_number() || !j[1].is_number() || !j[2].is_number())
    return absl::DataLossError(absl::StrCat(what, ": expected [x, y, z]"));
  return Eigen::Vector3d(j[0].get<double>(), j[1].get<double>(), j[2].get<double>());
}

void SetRotation(const Eigen::Quaterniond& q, v1::Pose* pose) {
  pose->set_qx(q.x());
  pose->set_qy(q.y());
  pose->set_qz(q.z());
  pose->set_qw(q.w());
}

// The artefacts of one object: the files of `manifest` under `prefix` (prefix stripped).
void AddArtefacts(const store::Manifest& manifest, const std::string& prefix, v1::Object* o) {
  for (const auto& [path, digest] : manifest.files) {
    if (!absl::StartsWith(path, prefix)) continue;
    v1::Artefact* a = o->add_artefacts();
    a->set_path(path.substr(prefix.size()));
    rpc::ToProto(digest, a->mutable_digest());
    a->set_media_type(MediaType(path));
  }
}

}  // namespace

std::string SceneOutputs::Key() const {
  std::string key = absl::StrCat(scene, "|", scene_manifest.hash, "|", segment.hash, "|",
                                 exported ? exported->hash : "-");
  for (const auto& [item, digest] : complete) absl::StrAppend(&key, "|", item, ":", digest.hash);
  return key;
}

absl::Status SceneObjects::LoadScene(store::BlobStore& store) {
  // scene.json and the splat only, straight from the store (nothing is written to disk).
  ASSIGN_OR_RETURN(store::Manifest scene_manifest,
                   store::ReadManifest(store, outputs_.scene_manifest));
  constexpr char kWhat[] = "the scene manifest";
  ASSIGN_OR_RETURN(const std::string scene_text,
                   ReadVerifiedFile(store, scene_manifest, "scene.json", kMaxJsonBytes, kWhat));
  ASSIGN_OR_RETURN(scene_, ParseSceneJson(scene_text, "scene.json"));
  ASSIGN_OR_RETURN(
      const std::string splat,
      ReadVerifiedFile(store, scene_manifest, scene_.gaussians, kMaxSplatBytes, kWhat));
  ASSIGN_OR_RETURN(cloud_, ParseSplatFile(splat, scene_.gaussians));
  meters_per_unit_ = scene_.meters_per_unit;
  return absl::OkStatus();
}

absl::Status SceneObjects::IndexLabels(store::BlobStore& store, const store::Manifest& segment) {
  constexpr char kWhat[] = "the segment output";
  ASSIGN_OR_RETURN(json result_json, ReadJsonBlob(store, segment, "result.json", kWhat));
  const std::string labels_file = result_json.value("labels", std::string("labels.ply"));
  ASSIGN_OR_RETURN(const std::string labels_ply,
                   ReadVerifiedFile(store, segment, labels_file, kMaxSplatBytes, kWhat));
  SegmentationResult result;
  ASSIGN_OR_RETURN(result.labels, ParseGaussianInstanceIds(labels_ply, labels_file, cloud_.size()));
  ASSIGN_OR_RETURN(index_, QueryIndex::Build(scene_, cloud_, result, 0, /*eager=*/false));
  const float diagonal = RobustBounds(cloud_).diagonal().norm();
  default_radius_ = 0.02f * diagonal;
  max_radius_ = diagonal;
  return absl::OkStatus();
}

size_t SceneObjects::HeldBytes() const {
  // The cloud, label maps, labels + members + k-d tree, the answers.
  const GaussianCloud& c = cloud_;
  size_t bytes = sizeof(float) * (c.positions.size() + c.log_scales.size() + c.rotations.size() +
                                  c.opacity_logits.size() + c.sh.size()) +
                 index_->ByteSize();
  for (const ExtraChannel& e : c.extras) bytes += sizeof(float) * e.values.size();
  for (const auto& [id, o] : objects_) bytes += o.SpaceUsedLong();
  return bytes;
}

absl::StatusOr<std::unique_ptr<SceneObjects>> SceneObjects::Load(store::BlobStore& store,
                                                                 const SceneOutputs& outputs) {
  auto loaded = std::unique_ptr<SceneObjects>(new SceneObjects());
  SceneObjects& s = *loaded;
  s.outputs_ = outputs;
  RETURN_IF_ERROR(s.LoadScene(store));
  ASSIGN_OR_RETURN(store::Manifest segment, store::ReadManifest(store, outputs.segment));
  RETURN_IF_ERROR(s.IndexLabels(store, segment));
  if (outputs.exported) {
    RETURN_IF_ERROR(s.LoadExport(store, *outputs.exported));
  } else if (!outputs.complete.empty()) {
    RETURN_IF_ERROR(s.LoadCompleted(store, outputs.complete));
  }
  s.AddSegmentOnly(segment);  // instances neither exported nor completed
  RETURN_IF_ERROR(s.AddSplats(store, segment, outputs.complete));
  s.bytes_ = s.HeldBytes();
  s.warm_up_ = std::thread([&s] {
    for (int v = 0; v < s.Views() && !s.stop_; ++v) {
      (void)s.index_->Click(v, 0, 0);  // renders the view's label map (errors resurface on clicks)
    }
  });
  return loaded;
}

SceneObjects::~SceneObjects() {
  stop_ = true;
  if (warm_up_.joinable()) warm_up_.join();  // at most one view's rendering
}

v1::Object SceneObjects::NewObject(uint32_t id, const std::string& source) const {
  v1::Object o;
  o.set_scene(outputs_.scene);
  o.set_id(id);
  o.set_source(source);
  o.set_units(meters_per_unit_ ? "metres" : "scene units (unscaled)");
  if (meters_per_unit_) o.set_meters_per_unit(*meters_per_unit_);
  o.set_gaussians(static_cast<int64_t>(index_->Gaussians(id).size()));
  rpc::ToProto(outputs_.segment, o.mutable_segment_manifest());
  return o;
}

absl::Status SceneObjects::LoadExport(store::BlobStore& store, const store::Digest& digest) {
  ASSIGN_OR_RETURN(store::Manifest exported, store::ReadManifest(store, digest));
  ASSIGN_OR_RETURN(json catalogue,
                   ReadJsonBlob(store, exported, "objects.json", "the export output"));
  if (!catalogue.contains("objects") || !catalogue["objects"].is_array())
    return absl::DataLossError("export output objects.json: no \"objects\" list");
  for (const json& entry : catalogue["objects"]) {
    if (!entry.is_object() || !entry.contains("id") || !entry["id"].is_number_unsigned() ||
        !entry.contains("dir") || !entry["dir"].is_string())
      return absl::DataLossError("export output objects.json: an entry without id or dir");
    const uint32_t id = entry["id"].get<uint32_t>();
    const std::string prefix = entry["dir"].get<std::string>() + "/";
    const std::string what = absl::StrCat("export object ", id);
    ASSIGN_OR_RETURN(json m, ReadJsonBlob(store, exported, prefix + "manifest.json", what));
    v1::Object o = NewObject(id, "export");
    o.set_units(m.value("units", o.units()));
    const json& pose = m.value("world_from_object", json::object());
    ASSIGN_OR_RETURN(Eigen::Vector3d t,
                     JsonVector(pose.value("translation", json()), what + " translation"));
    const json q = pose.value("quaternion_xyzw", json());
    if (!q.is_array() || q.size() != 4)
      return absl::DataLossError(absl::StrCat(what, ": world_from_object has no quaternion_xyzw"));
    SetVector(t, o.mutable_world_from_object()->mutable_translation());
    SetRotation(Eigen::Quaterniond(q[3].get<double>(), q[0].get<double>(), q[1].get<double>(),
                                   q[2].get<double>()),
                o.mutable_world_from_object());
    ASSIGN_OR_RETURN(
        Eigen::Vector3d extent,
        JsonVector(m.value("bounding_box", json::object()).value("extent", json()), what));
    SetVector(extent, o.mutable_extent());
    o.set_completion(m.value("completion", std::string()));
    o.set_completed_share(m.value("completed_share", 0.0));
    o.set_manifest_json(m.dump());
    AddArtefacts(exported, prefix, &o);
    rpc::ToProto(digest, o.mutable_export_manifest());
    objects_[id] = std::move(o);
  }
  return absl::OkStatus();
}

absl::Status SceneObjects::LoadCompleted(store::BlobStore& store,
                                         const std::map<int64_t, store::Digest>& items) {
  for (const auto& [item, digest] : items) {
    ASSIGN_OR_RETURN(store::Manifest completed, store::ReadManifest(store, digest));
    const std::string what = absl::StrCat("complete output ", item);
    ASSIGN_OR_RETURN(json m, ReadJsonBlob(store, completed, "manifest.json", what));
    if (!m.contains("id") || !m["id"].is_number_unsigned())
      return absl::DataLossError(absl::StrCat(what, ": manifest.json has no object id"));
    const uint32_t id = m["id"].get<uint32_t>();
    // world_from_object: a 3x4 [R | t] in scene units.
    const json& rows = m.value("world_from_object", json());
    if (!rows.is_array() || rows.size() != 3)
      return absl::DataLossError(absl::StrCat(what, ": world_from_object is not 3x4"));
    Eigen::Matrix3d r;
    Eigen::Vector3d t;
    for (int i = 0; i < 3; ++i) {
      if (!rows[i].is_array() || rows[i].size() != 4)
        return absl::DataLossError(absl::StrCat(what, ": world_from_object is not 3x4"));
      for (int k = 0; k < 3; ++k) r(i, k) = rows[i][k].get<double>();
      t[i] = rows[i][3].get<double>();
    }
    const double s = meters_per_unit_.value_or(1.0);
    v1::Object o = NewObject(id, "complete");
    SetVector(s * t, o.mutable_world_from_object()->mutable_translation());
    SetRotation(Eigen::Quaterniond(r).normalized(), o.mutable_world_from_object());
    ASSIGN_OR_RETURN(
        Eigen::Vector3d extent,
        JsonVector(m.value("bounding_box", json::object()).value("extent", json()), what));
    SetVector(s * extent, o.mutable_extent());
    const bool abstained = m.value("abstained", true);
    o.set_completion(abstained ? "abstained (closed crop)" : "completed");
    o.set_completed_share(m.value("gaussians", json::object()).value("completed_share", 0.0));
    o.set_manifest_json(m.dump());
    AddArtefacts(completed, "", &o);
    objects_[id] = std::move(o);
  }
  return absl::OkStatus();
}

void SceneObjects::AddSegmentOnly(const store::Manifest& segment) {
  const double s = meters_per_unit_.value_or(1.0);
  for (uint32_t id : index_->Instances()) {
    if (objects_.count(id)) continue;
    Eigen::AlignedBox3d box;
    const std::vector<uint32_t>& members = index_->Gaussians(id);
    for (uint32_t g : members) box.extend(Eigen::Vector3f(&cloud_.positions[3 * g]).cast<double>());
    v1::Object o = NewObject(id, "segment");
    // Axis-aligned: the box centre as origin, the world's axes.
    SetVector(s * box.center(), o.mutable_world_from_object()->mutable_translation());
    SetRotation(Eigen::Quaterniond::Identity(), o.mutable_world_from_object());
    SetVector(s * box.sizes(), o.mutable_extent());
    o.set_completion("raw crop (not completed)");
    const std::string splat = absl::StrCat("instances/", id, ".ply");
    auto it = segment.files.find(splat);
    if (it != segment.files.end()) {
      v1::Artefact* a = o.add_artefacts();
      a->set_path("splat.ply");
      rpc::ToProto(it->second, a->mutable_digest());
      a->set_media_type(MediaType(splat));
    }
    objects_[id] = std::move(o);
  }
}

absl::Status SceneObjects::AddSplats(store::BlobStore& store, const store::Manifest& segment,
                                     const std::map<int64_t, store::Digest>& complete) {
  auto has = [](const v1::Object& o, const std::string& path) {
    return std::any_of(o.artefacts().begin(), o.artefacts().end(),
                       [&](const v1::Artefact& a) { return a.path() == path; });
  };
  auto add = [&](v1::Object& o, const std::string& path, const store::Digest& digest) {
    if (has(o, path)) return;
    v1::Artefact* a = o.add_artefacts();
    a->set_path(path);
    rpc::ToProto(digest, a->mutable_digest());
    a->set_media_type(MediaType(path));
  };
  for (auto& [id, o] : objects_) {
    auto it = segment.files.find(absl::StrCat("instances/", id, ".ply"));
    if (it != segment.files.end()) add(o, "splat.ply", it->second);
  }
  for (const auto& [item, digest] : complete) {
    ASSIGN_OR_RETURN(store::Manifest completed, store::ReadManifest(store, digest));
    auto splat = completed.files.find("object.ply");
    if (splat == completed.files.end()) continue;
    ASSIGN_OR_RETURN(json m, ReadJsonBlob(store, completed, "manifest.json",
                                          absl::StrCat("complete output ", item)));
    if (!m.contains("id") || !m["id"].is_number_unsigned()) continue;
    auto o = objects_.find(m["id"].get<uint32_t>());
    if (o != objects_.end()) add(o->second, "object.ply", splat->second);
  }
  return absl::OkStatus();
}

absl::StatusOr<uint32_t> SceneObjects::Resolve(const v1::ObjectSelector& selector) const {
  switch (selector.selector_case()) {
    case v1::ObjectSelector::kId:
      if (objects_.count(selector.id()) == 0)
        return absl::NotFoundError(absl::StrCat("scene '", outputs_.scene, "' has no object ",
                                                selector.id(), " (", objects_.size(),
                                                " objects; ListObjects names them)"));
      return selector.id();
    case v1::ObjectSelector::kPoint:
      return ResolvePoint(selector.point(), selector.max_distance());
    case v1::ObjectSelector::kClick:
      return ResolveClick(selector.click());
    case v1::ObjectSelector::kRay:
      return ResolveRay(selector.ray());
    case v1::ObjectSelector::SELECTOR_NOT_SET:
      break;
  }
  return absl::InvalidArgumentError("selector: give one of id, point, click or ray");
}

absl::StatusOr<uint32_t> SceneObjects::ResolvePoint(const v1::Vector3& p,
                                                    double max_distance) const {
  const Eigen::Vector3d point(p.x(), p.y(), p.z());
  if (!point.allFinite()) return absl::InvalidArgumentError("selector.point is not finite");
  double radius = max_distance;
  if (!(radius >= 0) || radius > max_radius_)
    return absl::InvalidArgumentError(absl::StrFormat(
        "selector.max_distance %g: must be in [0, %g] (the scene's diagonal; 0 = %g)", radius,
        max_radius_, default_radius_));
  if (radius == 0) radius = default_radius_;
  ASSIGN_OR_RETURN(QueryAnswer a, index_->Point(point.cast<float>(), static_cast<float>(radius)));
  if (a.instance == 0 || objects_.count(a.instance) == 0)
    return absl::NotFoundError(
        absl::StrFormat("scene '%s': no object within %g scene units of (%g, %g, %g)",
                        outputs_.scene, radius, point.x(), point.y(), point.z()));
  return a.instance;
}

absl::StatusOr<uint32_t> SceneObjects::ResolveClick(const v1::PixelClick& c) const {
  ASSIGN_OR_RETURN(int view, ResolveView(scene_, c.view()));
  ASSIGN_OR_RETURN(QueryAnswer a, index_->Click(view, c.x(), c.y()));
  if (a.instance == 0 || objects_.count(a.instance) == 0)
    return absl::NotFoundError(
        absl::StrFormat("scene '%s': pixel (%d, %d) of view %s shows the background, no object",
                        outputs_.scene, c.x(), c.y(), scene_.views[view].name));
  return a.instance;
}

absl::StatusOr<uint32_t> SceneObjects::ResolveRay(const v1::Ray& r) const {
  const Eigen::Vector3d o(r.origin().x(), r.origin().y(), r.origin().z());
  const Eigen::Vector3d d(r.direction().x(), r.direction().y(), r.direction().z());
  ASSIGN_OR_RETURN(QueryAnswer a, index_->Ray(o.cast<float>(), d.cast<float>()));
  if (a.instance == 0 || objects_.count(a.instance) == 0)
    return absl::NotFoundError(
        absl::StrFormat("scene '%s': the ray from (%g, %g, %g) along (%g, %g, %g) meets no object",
                        outputs_.scene, o.x(), o.y(), o.z(), d.x(), d.y(), d.z()));
  return a.instance;
}

absl::StatusOr<v1::Object> SceneObjects::Describe(uint32_t id) const {
  auto it = objects_.find(id);
  if (it == objects_.end())
    return absl::NotFoundError(absl::StrCat("scene '", outputs_.scene, "' has no object ", id));
  return it->second;
}

std::vector<uint32_t> SceneObjects::Ids() const {
  std::vector<uint32_t> ids;
  for (const auto& [id, o] : objects_) ids.push_back(id);
  return ids;
}

}  // namespace instascene::objects
