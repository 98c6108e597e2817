#include "common/scene/image_io.h"

#include "common/scene/scene.h"

#include <unistd.h>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "absl/strings/str_cat.h"
#include "common/core/file_io.h"
#include "common/core/status.h"

namespace instascene {
namespace {

constexpr int kMaxImageSide = 16384;

absl::Status OiioError(const std::string& path, const std::string& what,
                       const std::string& detail) {
  return absl::InvalidArgumentError(
      absl::StrCat(path, ": ", what, detail.empty() ? "" : ": ", detail));
}

// Encodes in memory (the format follows the extension), then writes through the project's one
// durable atomic write (common/core/file_io.h).
absl::Status WritePixels(const std::string& path, int width, int height, int channels,
                         const OIIO::TypeDesc& format, const void* data) {
  auto out = OIIO::ImageOutput::create(path);
  if (!out) return OiioError(path, "no writer for this extension", OIIO::geterror());
  if (!out->supports("ioproxy"))
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": ", out->format_name(), " cannot be encoded in memory"));
  std::vector<unsigned char> encoded;
  OIIO::Filesystem::IOVecOutput proxy(encoded);
  OIIO::ImageSpec spec(width, height, channels, format);
  if (!out->set_ioproxy(&proxy) || !out->open(path, spec) || !out->write_image(format, data) ||
      !out->close())
    return absl::UnavailableError(absl::StrCat(path, ": encoding failed: ", out->geterror()));
  return WriteFileAtomically(
      path, absl::string_view(reinterpret_cast<const char*>(encoded.data()), encoded.size()));
}

}  // namespace

absl::StatusOr<Image> ReadImage(const std::string& path) {
  if (!std::filesystem::is_regular_file(path))
    return absl::NotFoundError(absl::StrCat(path, ": no such file"));
  auto in = OIIO::ImageInput::open(path);
  if (!in) return OiioError(path, "cannot decode image", OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.width <= 0 || spec.height <= 0 || spec.width > kMaxImageSide ||
      spec.height > kMaxImageSide || spec.nchannels <= 0 || spec.nchannels > 4) {
    return OiioError(
        path,
        absl::StrCat("unsupported image size ", spec.width, "x", spec.height, "x", spec.nchannels),
        "");
  }
  Image image;
  image.width = spec.width;
  image.height = spec.height;
  image.channels = spec.nchannels;
  image.pixels.resize(static_cast<size_t>(spec.width) * spec.height * spec.nchannels);
  if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, image.pixels.data())) {
    return absl::DataLossError(
        absl::StrCat(path, ": truncated or corrupt image: ", in->geterror()));
  }
  return image;
}

absl::Status WriteImage(const std::string& path, const Image& image, int bits) {
  const size_t n = static_cast<size_t>(image.width) * image.height * image.channels;
  if (image.pixels.size() != n || n == 0)
    return absl::InvalidArgumentError(absl::StrCat(path, ": image buffer size mismatch"));
  if (bits == 16) {
    std::vector<uint16_t> data(n);
    for (size_t i = 0; i < n; ++i)
      data[i] =
          static_cast<uint16_t>(std::lround(std::clamp(image.pixels[i], 0.0f, 1.0f) * 65535.0f));
    return WritePixels(path, image.width, image.height, image.channels, OIIO::TypeDesc::UINT16,
                       data.data());
  }
  std::vector<uint8_t> data(n);
  for (size_t i = 0; i < n; ++i)
    data[i] = static_cast<uint8_t>(std::lround(std::clamp(image.pixels[i], 0.0f, 1.0f) * 255.0f));
  return WritePixels(path, image.width, image.height, image.channels, OIIO::TypeDesc::UINT8,
                     data.data());
}

absl::StatusOr<LabelMap> ReadLabelMap(const std::string& path) {
  if (!std::filesystem::is_regular_file(path))
    return absl::NotFoundError(absl::StrCat(path, ": no such file"));
  auto in = OIIO::ImageInput::open(path);
  if (!in) return OiioError(path, "cannot decode label map", OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.nchannels != 1) {
    return OiioError(path, absl::StrCat("label map must have 1 channel, has ", spec.nchannels), "");
  }
  if (spec.format != OIIO::TypeDesc::UINT8 && spec.format != OIIO::TypeDesc::UINT16) {
    return OiioError(
        path, absl::StrCat("label map must be 8- or 16-bit integer, is ", spec.format.c_str()), "");
  }
  if (spec.width <= 0 || spec.height <= 0 || spec.width > kMaxImageSide ||
      spec.height > kMaxImageSide) {
    return OiioError(path, "unsupported label map size", "");
  }
  LabelMap map;
  map.width = spec.width;
  map.height = spec.height;
  map.labels.resize(static_cast<size_t>(spec.width) * spec.height);
  if (!in->read_image(0, 0, 0, 1, OIIO::TypeDesc::UINT16, map.labels.data())) {
    return absl::DataLossError(
        absl::StrCat(path, ": truncated or corrupt label map: ", in->geterror()));
  }
  if (spec.format == OIIO::TypeDesc::UINT8) {
    // OIIO rescales 8-bit to the 16-bit range (v * 257); undo it to keep the ids.
    for (uint16_t& v : map.labels) v = static_cast<uint16_t>(v / 257);
  }
  return map;
}

absl::Status WriteLabelMap(const std::string& path, const LabelMap& labels) {
  if (labels.labels.size() != static_cast<size_t>(labels.width) * labels.height ||
      labels.labels.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": label buffer size mismatch"));
  }
  return WritePixels(path, labels.width, labels.height, 1, OIIO::TypeDesc::UINT16,
                     labels.labels.data());
}

absl::StatusOr<Image> ReadViewImage(const Scene& scene, int view) {
  const SceneView& v = scene.views.at(view);
  if (v.image.empty()) return absl::NotFoundError(absl::StrCat("view '", v.name, "' has no image"));
  ASSIGN_OR_RETURN(Image image, ReadImage(scene.Path(v.image)));
  if (image.width != v.camera.width || image.height != v.camera.height) {
    return absl::InvalidArgumentError(
        absl::StrCat(scene.Path(v.image), ": image is ", image.width, "x", image.height,
                     " but view '", v.name, "' camera is ", v.camera.width, "x", v.camera.height));
  }
  return image;
}

absl::StatusOr<LabelMap> ReadViewMask(const Scene& scene, int view) {
  const SceneView& v = scene.views.at(view);
  if (v.mask.empty()) return absl::NotFoundError(absl::StrCat("view '", v.name, "' has no mask"));
  ASSIGN_OR_RETURN(LabelMap mask, ReadLabelMap(scene.Path(v.mask)));
  if (mask.width != v.camera.width || mask.height != v.camera.height) {
    return absl::InvalidArgumentError(
        absl::StrCat(scene.Path(v.mask), ": mask is ", mask.width, "x", mask.height, " but view '",
                     v.name, "' camera is ", v.camera.width, "x", v.camera.height));
  }
  return mask;
}

}  // namespace instascene
