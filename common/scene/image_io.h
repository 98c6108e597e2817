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
// Reads a view's image / mask and checks its size against the view's camera.
absl::StatusOr<Image> ReadViewImage(const Scene& scene, int view);
absl::StatusOr<LabelMap> ReadViewMask(const Scene& scene, int view);

}  // namespace instascene
