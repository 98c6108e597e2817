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

absl::StatusOr<ImageHeader> HeaderOf(const OIIO::ImageSpec& spec, const std::string& name) {
  if (spec.width <= 0 || spec.height <= 0 || spec.width > kMaxImageSide ||
      spec.height > kMaxImageSide || int64_t{spec.width} * spec.height > kMaxImagePixels ||
      spec.nchannels <= 0 || spec.nchannels > 4) {
    return OiioError(name,
                     absl::StrCat("unsupported image size ", spec.width, "x", spec.height, "x",
                                  spec.nchannels, " (at most ", kMaxImageSide, " px per side, ",
                                  kMaxImagePixels, " pixels, 4 channels)"),
                     "");
  }
  ImageHeader h;
  h.width = spec.width;
  h.height = spec.height;
  h.channels = spec.nchannels;
  h.label_map = spec.nchannels == 1 &&
                (spec.format == OIIO::TypeDesc::UINT8 || spec.format == OIIO::TypeDesc::UINT16);
  return h;
}

// Opens `path` for decoding after checking it is a regular file and its header within limits.
absl::StatusOr<std::unique_ptr<OIIO::ImageInput>> OpenChecked(const std::string& path,
                                                              const char* what) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    return absl::NotFoundError(absl::StrCat(path, ": no such file (or not a regular file)"));
  auto in = OIIO::ImageInput::open(path);
  if (!in) return OiioError(path, absl::StrCat("cannot decode ", what), OIIO::geterror());
  RETURN_IF_ERROR(HeaderOf(in->spec(), path).status());
  return in;
}

}  // namespace

absl::StatusOr<ImageHeader> ProbeImage(const std::string& path) {
  ASSIGN_OR_RETURN(std::unique_ptr<OIIO::ImageInput> in, OpenChecked(path, "image"));
  return HeaderOf(in->spec(), path);
}

absl::StatusOr<ImageHeader> ProbeImageBytes(absl::string_view bytes, const std::string& name) {
  OIIO::Filesystem::IOMemReader proxy(bytes.data(), bytes.size());
  // The reader from the extension alone (create() given a path would read the file itself).
  const std::string extension = std::filesystem::path(name).extension().string();
  auto in = extension.size() > 1 ? OIIO::ImageInput::create(extension.substr(1), false) : nullptr;
  if (!in) return OiioError(name, "no reader for this extension", OIIO::geterror());
  if (!in->supports("ioproxy"))
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": ", in->format_name(), " images cannot be probed in memory"));
  OIIO::ImageSpec spec;
  if (!in->set_ioproxy(&proxy) || !in->open(name, spec))
    return absl::DataLossError(absl::StrCat(name, ": unreadable image header: ", in->geterror()));
  return HeaderOf(spec, name);
}

absl::StatusOr<Image> ReadImage(const std::string& path) {
  ASSIGN_OR_RETURN(std::unique_ptr<OIIO::ImageInput> in, OpenChecked(path, "image"));
  const OIIO::ImageSpec& spec = in->spec();
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
  ASSIGN_OR_RETURN(std::unique_ptr<OIIO::ImageInput> in, OpenChecked(path, "label map"));
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.nchannels != 1) {
    return OiioError(path, absl::StrCat("label map must have 1 channel, has ", spec.nchannels), "");
  }
  if (spec.format != OIIO::TypeDesc::UINT8 && spec.format != OIIO::TypeDesc::UINT16) {
    return OiioError(
        path, absl::StrCat("label map must be 8- or 16-bit integer, is ", spec.format.c_str()), "");
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
  ASSIGN_OR_RETURN(ImageHeader header, ProbeImage(scene.Path(v.image)));
  if (header.width != v.camera.width || header.height != v.camera.height) {
    return absl::InvalidArgumentError(
        absl::StrCat(scene.Path(v.image), ": image is ", header.width, "x", header.height,
                     " but view '", v.name, "' camera is ", v.camera.width, "x", v.camera.height));
  }
  return ReadImage(scene.Path(v.image));
}

absl::StatusOr<LabelMap> ReadViewMask(const Scene& scene, int view) {
  const SceneView& v = scene.views.at(view);
  if (v.mask.empty()) return absl::NotFoundError(absl::StrCat("view '", v.name, "' has no mask"));
  ASSIGN_OR_RETURN(ImageHeader header, ProbeImage(scene.Path(v.mask)));
  if (header.width != v.camera.width || header.height != v.camera.height) {
    return absl::InvalidArgumentError(
        absl::StrCat(scene.Path(v.mask), ": mask is ", header.width, "x", header.height,
                     " but view '", v.name, "' camera is ", v.camera.width, "x", v.camera.height));
  }
  return ReadLabelMap(scene.Path(v.mask));
}

absl::Status CheckViewFiles(const Scene& scene) {
  for (const SceneView& v : scene.views) {
    for (const std::string* rel : {&v.image, &v.mask}) {
      if (rel->empty()) continue;
      ASSIGN_OR_RETURN(ImageHeader header, ProbeImage(scene.Path(*rel)));
      const char* what = rel == &v.image ? "image" : "mask";
      if (header.width != v.camera.width || header.height != v.camera.height) {
        return absl::InvalidArgumentError(absl::StrCat(
            scene.Path(*rel), ": ", what, " is ", header.width, "x", header.height, " but view '",
            v.name, "' camera is ", v.camera.width, "x", v.camera.height));
      }
      if (rel == &v.mask && !header.label_map) {
        return absl::InvalidArgumentError(
            absl::StrCat(scene.Path(*rel), ": mask of view '", v.name,
                         "' must be a single-channel 8- or 16-bit integer image, has ",
                         header.channels, " channels"));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace instascene
