// common/scene/image_io.h: images and label maps on disk, through OpenImageIO.
//
// OpenImageIO is the one choke point for image files: every OIIO error becomes an absl::Status
// naming the file. Images are float RGB(A) in [0, 1]; label maps are 8- or 16-bit single-channel
// PNGs (0 = no label) held as uint16. Thread-safe: no shared state.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace instascene {

struct Image {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::vector<float> pixels;  // row-major, interleaved channels, [0, 1]
};

struct LabelMap {
  int width = 0;
  int height = 0;
  std::vector<uint16_t> labels;  // row-major, 0 = no label
};

// What an image file's header says, read without decoding any pixel.
struct ImageHeader {
  int width = 0;
  int height = 0;
  int channels = 0;
  bool label_map = false;  // single-channel 8- or 16-bit integer: usable as a mask
};
// Largest image side and pixel count read (a header can claim anything; decoding allocates what
// it claims): 16384 px per side, 64 M pixels.
inline constexpr int kMaxImageSide = 16384;
inline constexpr int64_t kMaxImagePixels = int64_t{64} << 20;

// Header only; only regular files. Sizes beyond the limits above are refused.
absl::StatusOr<ImageHeader> ProbeImage(const std::string& path);
// The same from the first bytes of an image (the upload check reads a prefix from the store);
// `name` is used in errors. A prefix too short to hold the header is a DATA_LOSS error.
absl::StatusOr<ImageHeader> ProbeImageBytes(absl::string_view bytes, const std::string& name);

// Reads any format OpenImageIO knows (PNG, JPEG, EXR, ...).
absl::StatusOr<Image> ReadImage(const std::string& path);
// Writes 8-bit (or 16-bit when bits == 16) PNG/JPEG by extension; values clamped to [0, 1].
// Encoded in memory and written atomically and durably (common/core/file_io.h).
absl::Status WriteImage(const std::string& path, const Image& image, int bits = 8);

// Reads a single-channel 8- or 16-bit integer label map; rejects multi-channel and float images.
absl::StatusOr<LabelMap> ReadLabelMap(const std::string& path);
// Writes a 16-bit single-channel PNG (atomically).
absl::Status WriteLabelMap(const std::string& path, const LabelMap& labels);

struct Scene;
// Reads a view's image / mask, its header checked against the view's camera before any pixel is
// decoded.
absl::StatusOr<Image> ReadViewImage(const Scene& scene, int view);
absl::StatusOr<LabelMap> ReadViewMask(const Scene& scene, int view);
// Probes every view's image and mask (headers only): regular files, the camera's size, masks
// single-channel 8/16-bit integer. What `submit` checks before uploading anything.
absl::Status CheckViewFiles(const Scene& scene);

}  // namespace instascene
