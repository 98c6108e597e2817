#include "common/scene/importers.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/splat/ply.h"

namespace instascene {
namespace {

struct ColmapCamera {
  int model_id = -1;
  int width = 0, height = 0;
  std::vector<double> params;
};

struct ColmapModel {
  const char* name;
  int num_params;
  bool distorted;
  bool fisheye;
};

// COLMAP's camera models, by model id.
constexpr ColmapModel kModels[] = {
    {"SIMPLE_PINHOLE", 3, false, false},
    {"PINHOLE", 4, false, false},
    {"SIMPLE_RADIAL", 4, true, false},
    {"RADIAL", 5, true, false},
    {"OPENCV", 8, true, false},
    {"OPENCV_FISHEYE", 8, true, true},
    {"FULL_OPENCV", 12, true, false},
    {"FOV", 5, true, true},
    {"SIMPLE_RADIAL_FISHEYE", 4, true, true},
    {"RADIAL_FISHEYE", 5, true, true},
    {"THIN_PRISM_FISHEYE", 12, true, true},
};
constexpr int kNumModels = sizeof(kModels) / sizeof(kModels[0]);

int ModelIdFromName(const std::string& name) {
  for (int i = 0; i < kNumModels; ++i) {
    if (name == kModels[i].name) return i;
  }
  return -1;
}

// Intrinsics of a COLMAP camera as a pinhole; rejects distortion unless assumed undistorted.
absl::Status ToPinhole(const ColmapCamera& cam, int camera_id, const ImportOptions& options,
                       PinholeCamera* out) {
  const ColmapModel& model = kModels[cam.model_id];
  if (model.fisheye) {
    return absl::InvalidArgumentError(
        absl::StrCat("camera ", camera_id, ": fisheye model ", model.name,
                     " is not supported; undistort the images first"));
  }
  if (model.distorted && !options.assume_undistorted) {
    return absl::InvalidArgumentError(absl::StrCat(
        "camera ", camera_id, ": model ", model.name,
        " has lens distortion; run COLMAP image_undistorter, or pass --assume-undistorted if the "
        "images are already undistorted"));
  }
  const bool single_focal = cam.model_id == 0 || cam.model_id == 2 || cam.model_id == 3;
  out->width = cam.width;
  out->height = cam.height;
  out->fx = cam.params[0];
  out->fy = single_focal ? cam.params[0] : cam.params[1];
  out->cx = single_focal ? cam.params[1] : cam.params[2];
  out->cy = single_focal ? cam.params[2] : cam.params[3];
  return out->Validate();
}

// Bounds-checked little-endian reader over a whole file.
class BinaryReader {
 public:
  BinaryReader(const std::string& data, std::string source)
      : data_(data), source_(std::move(source)) {}
  template <typename T>
  absl::Status Read(T* value) {
    if (data_.size() - pos_ < sizeof(T)) return Truncated();
    std::memcpy(value, data_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return absl::OkStatus();
  }
  absl::Status ReadString(std::string* value) {
    const size_t end = data_.find('\0', pos_);
    if (end == std::string::npos || end - pos_ > 4096) return Truncated();
    *value = data_.substr(pos_, end - pos_);
    pos_ = end + 1;
    return absl::OkStatus();
  }
  absl::Status Skip(uint64_t bytes) {
    if (data_.size() - pos_ < bytes) return Truncated();
    pos_ += bytes;
    return absl::OkStatus();
  }
  size_t remaining() const { return data_.size() - pos_; }
  absl::Status Truncated() const {
    return absl::InvalidArgumentError(absl::StrCat(source_, ": truncated at byte ", pos_));
  }

 private:
  const std::string& data_;
  std::string source_;
  size_t pos_ = 0;
};

absl::StatusOr<std::map<int, ColmapCamera>> ReadCamerasBin(const std::string& path) {
  ASSIGN_OR_RETURN(std::string data, ReadFileBounded(path, size_t{1} << 30));
  BinaryReader in(data, path);
  uint64_t count = 0;
  RETURN_IF_ERROR(in.Read(&count));
  if (count > in.remaining() / 24) return in.Truncated();
  std::map<int, ColmapCamera> cameras;
  for (uint64_t i = 0; i < count; ++i) {
    uint32_t id = 0;
    int32_t model = 0;
    uint64_t w = 0, h = 0;
    RETURN_IF_ERROR(in.Read(&id));
    RETURN_IF_ERROR(in.Read(&model));
    RETURN_IF_ERROR(in.Read(&w));
    RETURN_IF_ERROR(in.Read(&h));
    if (model < 0 || model >= kNumModels) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": camera ", id, " has unknown model id ", model));
    }
    if (w > 16384 || h > 16384)
      return absl::InvalidArgumentError(absl::StrCat(path, ": camera ", id, " size out of range"));
    ColmapCamera cam{model, static_cast<int>(w), static_cast<int>(h),
                     std::vector<double>(kModels[model].num_params)};
    for (double& p : cam.params) RETURN_IF_ERROR(in.Read(&p));
    cameras[static_cast<int>(id)] = cam;
  }
  return cameras;
}

struct ColmapImage {
  std::string name;
  int camera_id = 0;
  double q[4], t[3];
};

absl::StatusOr<std::vector<ColmapImage>> ReadImagesBin(const std::string& path) {
  ASSIGN_OR_RETURN(std::string data, ReadFileBounded(path, size_t{8} << 30));
  BinaryReader in(data, path);
  uint64_t count = 0;
  RETURN_IF_ERROR(in.Read(&count));
  if (count > in.remaining() / 64) return in.Truncated();
  std::vector<ColmapImage> images;
  for (uint64_t i = 0; i < count; ++i) {
    ColmapImage image;
    uint32_t image_id = 0, camera_id = 0;
    RETURN_IF_ERROR(in.Read(&image_id));
    for (double& v : image.q) RETURN_IF_ERROR(in.Read(&v));
    for (double& v : image.t) RETURN_IF_ERROR(in.Read(&v));
    RETURN_IF_ERROR(in.Read(&camera_id));
    RETURN_IF_ERROR(in.ReadString(&image.name));
    uint64_t num_points = 0;
    RETURN_IF_ERROR(in.Read(&num_points));
    if (num_points > in.remaining() / 24) return in.Truncated();
    RETURN_IF_ERROR(in.Skip(num_points * 24));
    image.camera_id = static_cast<int>(camera_id);
    images.push_back(std::move(image));
  }
  return images;
}

// Non-comment, non-empty lines of a COLMAP text file (images.txt keeps its empty points lines).
absl::StatusOr<std::vector<std::string>> TextLines(const std::string& path, bool keep_empty) {
  ASSIGN_OR_RETURN(std::string data, ReadFileBounded(path, size_t{8} << 30));
  std::vector<std::string> lines;
  std::istringstream in(data);
  std::string line;
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (!line.empty() && line[0] == '#') continue;
    if (line.empty() && !keep_empty) continue;
    lines.push_back(line);
  }
  return lines;
}

absl::StatusOr<std::map<int, ColmapCamera>> ReadCamerasTxt(const std::string& path) {
  ASSIGN_OR_RETURN(std::vector<std::string> lines, TextLines(path, false));
  std::map<int, ColmapCamera> cameras;
  for (size_t l = 0; l < lines.size(); ++l) {
    std::istringstream in(lines[l]);
    int id = 0;
    std::string model_name;
    ColmapCamera cam;
    if (!(in >> id >> model_name >> cam.width >> cam.height)) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": malformed camera line ", l + 1));
    }
    cam.model_id = ModelIdFromName(model_name);
    if (cam.model_id < 0)
      return absl::InvalidArgumentError(absl::StrCat(path, ": unknown camera model ", model_name));
    cam.params.resize(kModels[cam.model_id].num_params);
    for (double& p : cam.params) {
      if (!(in >> p))
        return absl::InvalidArgumentError(
            absl::StrCat(path, ": camera ", id, " has too few parameters"));
    }
    cameras[id] = cam;
  }
  return cameras;
}

absl::StatusOr<std::vector<ColmapImage>> ReadImagesTxt(const std::string& path) {
  ASSIGN_OR_RETURN(std::vector<std::string> lines, TextLines(path, true));
  std::vector<ColmapImage> images;
  for (size_t l = 0; l < lines.size(); l += 2) {
    if (lines[l].empty()) {
      --l;
      continue;
    }  // tolerate stray empty lines between records
    std::istringstream in(lines[l]);
    int image_id = 0;
    ColmapImage image;
    if (!(in >> image_id >> image.q[0] >> image.q[1] >> image.q[2] >> image.q[3] >> image.t[0] >>
          image.t[1] >> image.t[2] >> image.camera_id >> image.name)) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": malformed image line: '", lines[l], "'"));
    }
    images.push_back(std::move(image));
  }
  return images;
}

void SortByName(std::vector<SceneView>* views) {
  std::sort(views->begin(), views->end(),
            [](const SceneView& a, const SceneView& b) { return a.name < b.name; });
}

}  // namespace

absl::StatusOr<ImportedCameras> ImportColmapModel(const std::string& model_dir,
                                                  const ImportOptions& options) {
  namespace fs = std::filesystem;
  const bool binary = fs::exists(fs::path(model_dir) / "cameras.bin");
  std::map<int, ColmapCamera> cameras;
  std::vector<ColmapImage> images;
  if (binary) {
    ASSIGN_OR_RETURN(cameras, ReadCamerasBin((fs::path(model_dir) / "cameras.bin").string()));
    ASSIGN_OR_RETURN(images, ReadImagesBin((fs::path(model_dir) / "images.bin").string()));
  } else {
    ASSIGN_OR_RETURN(cameras, ReadCamerasTxt((fs::path(model_dir) / "cameras.txt").string()));
    ASSIGN_OR_RETURN(images, ReadImagesTxt((fs::path(model_dir) / "images.txt").string()));
  }
  ImportedCameras out;
  for (const ColmapImage& image : images) {
    auto it = cameras.find(image.camera_id);
    if (it == cameras.end()) {
      return absl::InvalidArgumentError(absl::StrCat(
          model_dir, ": image '", image.name, "' refers to missing camera ", image.camera_id));
    }
    SceneView view;
    view.name = fs::path(image.name).stem().string();
    view.image = image.name;
    RETURN_IF_ERROR(Annotate(ToPinhole(it->second, it->first, options, &view.camera), model_dir));
    view.camera.camera_from_world.rotation =
        RotationFromQuaternionWxyz(image.q[0], image.q[1], image.q[2], image.q[3]);
    view.camera.camera_from_world.translation = Eigen::Vector3d(image.t[0], image.t[1], image.t[2]);
    if (!view.camera.camera_from_world.translation.allFinite() ||
        !view.camera.camera_from_world.rotation.allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat(model_dir, ": image '", image.name, "' has a non-finite pose"));
    }
    out.views.push_back(std::move(view));
  }
  SortByName(&out.views);
  return out;
}

}  // namespace instascene
