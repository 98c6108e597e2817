#include "common/eval/result.h"

#include <filesystem>
#include <map>

#include <Eigen/Geometry>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/splat/ply.h"

namespace instascene {
namespace {

absl::StatusOr<PlyColumns> ReadVertexColumns(const std::string& path) {
  ASSIGN_OR_RETURN(std::string data, ReadFileBounded(path, size_t{8} << 30));
  ASSIGN_OR_RETURN(PlyHeader header, ParsePlyHeader(data, path));
  return ReadPlyElement(data, header, "vertex", path);
}

// The per-Gaussian feature columns f_0 .. f_{dim-1}.
PlyColumns FeatureColumns(const SegmentationResult& result) {
  const size_t n = result.labels.size();
  PlyColumns features;
  features.count = static_cast<int64_t>(n);
  for (int d = 0; d < result.feature_dim; ++d) {
    features.names.push_back(absl::StrCat("f_", d));
    features.types.push_back(ScalarType::kFloat32);
    std::vector<float> column(n);
    for (size_t i = 0; i < n; ++i) column[i] = result.features[i * result.feature_dim + d];
    features.columns.push_back(std::move(column));
  }
  return features;
}

// Per instance: its Gaussian count, centroid and bounds.
nlohmann::json InstanceSummaries(const SegmentationResult& result, const GaussianCloud& cloud) {
  // Eigen's vectors are not zeroed by their default constructor: every member starts explicitly.
  struct Summary {
    size_t count = 0;
    Eigen::AlignedBox3f box;  // empty
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  };
  std::map<uint32_t, Summary> instances;
  for (size_t i = 0; i < result.labels.size(); ++i) {
    if (result.labels[i] == 0) continue;
    const Eigen::Vector3f p(&cloud.positions[3 * i]);
    Summary& entry = instances[result.labels[i]];
    ++entry.count;
    entry.box.extend(p);
    entry.sum += p.cast<double>();
  }
  nlohmann::json list = nlohmann::json::array();
  for (const auto& [id, entry] : instances) {
    const Eigen::Vector3d c = entry.sum / static_cast<double>(entry.count);
    list.push_back(
        {{"id", id},
         {"gaussians", entry.count},
         {"centroid", {c.x(), c.y(), c.z()}},
         {"bounds_min", {entry.box.min().x(), entry.box.min().y(), entry.box.min().z()}},
         {"bounds_max", {entry.box.max().x(), entry.box.max().y(), entry.box.max().z()}}});
  }
  return list;
}

}  // namespace

absl::Status WriteResult(const std::string& directory, const SegmentationResult& result,
                         const GaussianCloud& cloud) {
  const size_t n = result.labels.size();
  if (n != cloud.size()) {
    return absl::InvalidArgumentError(
        absl::StrCat("result has ", n, " labels for ", cloud.size(), " Gaussians"));
  }
  if (result.feature_dim < 0 ||
      result.features.size() != n * static_cast<size_t>(result.feature_dim)) {
    return absl::InvalidArgumentError("result features do not match labels x feature_dim");
  }
  std::error_code ec;
  std::filesystem::create_directories(directory, ec);
  if (ec) return absl::UnavailableError(absl::StrCat(directory, ": cannot create: ", ec.message()));
  const std::filesystem::path dir(directory);
  PlyColumns labels;
  labels.count = static_cast<int64_t>(n);
  labels.names = {"instance_id"};
  labels.types = {ScalarType::kUint32};
  labels.columns = {std::vector<float>(result.labels.begin(), result.labels.end())};
  RETURN_IF_ERROR(
      WriteFileAtomically((dir / "labels.ply").string(), EncodePlyBinary("vertex", labels)));
  nlohmann::json j = result.metadata;
  j["format"] = kResultFormat;
  j["stage"] = result.stage;
  j["gaussians"] = n;
  j["labels"] = "labels.ply";
  j["feature_dim"] = result.feature_dim;
  if (result.feature_dim > 0) {
    RETURN_IF_ERROR(WriteFileAtomically((dir / "features.ply").string(),
                                        EncodePlyBinary("vertex", FeatureColumns(result))));
    j["features"] = "features.ply";
  }
  j["instances"] = InstanceSummaries(result, cloud);
  return WriteFileAtomically((dir / "result.json").string(), j.dump(1));
}

absl::StatusOr<SegmentationResult> ReadResult(const std::string& directory,
                                              size_t expected_gaussians) {
  const std::filesystem::path dir(directory);
  const std::string json_path = (dir / "result.json").string();
  ASSIGN_OR_RETURN(std::string text, ReadFileBounded(json_path, size_t{256} << 20));
  nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object())
    return absl::InvalidArgumentError(absl::StrCat(json_path, ": not a JSON object"));
  if (!j.contains("format") || !j["format"].is_string() || j["format"] != kResultFormat) {
    return absl::InvalidArgumentError(
        absl::StrCat(json_path, ": \"format\" must be \"", kResultFormat, "\""));
  }
  SegmentationResult result;
  result.stage = j.value("stage", std::string("unknown"));
  const std::string labels_file = j.value("labels", std::string("labels.ply"));
  if (labels_file.find("..") != std::string::npos || labels_file.empty() || labels_file[0] == '/') {
    return absl::InvalidArgumentError(absl::StrCat(json_path, ": unsafe labels path"));
  }
  ASSIGN_OR_RETURN(std::vector<uint32_t> labels,
                   ReadGaussianInstanceIds((dir / labels_file).string(), expected_gaussians));
  result.labels = std::move(labels);
  if (j.contains("features") && j["features"].is_string()) {
    const std::string path = (dir / j["features"].get<std::string>()).string();
    ASSIGN_OR_RETURN(PlyColumns cols, ReadVertexColumns(path));
    if (static_cast<size_t>(cols.count) != expected_gaussians) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": ", cols.count, " rows for ", expected_gaussians, " Gaussians"));
    }
    const int dim = static_cast<int>(cols.names.size());
    for (int d = 0; d < dim; ++d) {
      if (cols.Find(absl::StrCat("f_", d)) != d)
        return absl::InvalidArgumentError(absl::StrCat(path, ": properties must be f_0..f_D-1"));
    }
    result.feature_dim = dim;
    result.features.resize(expected_gaussians * dim);
    for (int d = 0; d < dim; ++d) {
      for (size_t i = 0; i < expected_gaussians; ++i)
        result.features[i * dim + d] = cols.columns[d][i];
    }
  }
  for (auto it = j.begin(); it != j.end(); ++it) {
    if (it.key() != "format" && it.key() != "stage" && it.key() != "labels" &&
        it.key() != "features") {
      result.metadata[it.key()] = it.value();
    }
  }
  return result;
}

absl::StatusOr<std::vector<uint32_t>> ParseGaussianInstanceIds(absl::string_view data,
                                                               absl::string_view source,
                                                               size_t expected_gaussians) {
  ASSIGN_OR_RETURN(PlyHeader header, ParsePlyHeader(data, source));
  ASSIGN_OR_RETURN(PlyColumns cols, ReadPlyElement(data, header, "vertex", source));
  const int c = cols.Find("instance_id");
  if (c < 0) return absl::InvalidArgumentError(absl::StrCat(source, ": no 'instance_id' property"));
  if (static_cast<size_t>(cols.count) != expected_gaussians) {
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": ", cols.count, " labels for ", expected_gaussians, " Gaussians"));
  }
  std::vector<uint32_t> ids(cols.count);
  for (int64_t i = 0; i < cols.count; ++i) {
    const float v = cols.columns[c][i];
    if (!(v >= 0.0f) || v != std::floor(v)) {
      return absl::InvalidArgumentError(
          absl::StrCat(source, ": element #", i, " has invalid instance_id ", v));
    }
    ids[i] = static_cast<uint32_t>(v);
  }
  return ids;
}

absl::StatusOr<std::vector<uint32_t>> ReadGaussianInstanceIds(const std::string& path,
                                                              size_t expected_gaussians) {
  ASSIGN_OR_RETURN(std::string data, ReadFileBounded(path, size_t{8} << 30));
  return ParseGaussianInstanceIds(data, path, expected_gaussians);
}

}  // namespace instascene
