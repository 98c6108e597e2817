// libFuzzer harness: image header probing (the check every view's image and mask passes before a
// pixel is decoded) on arbitrary bytes. The first byte picks the format the name announces.
#include <cstddef>
#include <cstdint>
#include <string>

#include "common/scene/image_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  static const char* kNames[] = {"view.png", "view.jpg", "view.tif", "view.exr"};
  const std::string name = kNames[data[0] % 4];
  auto header = instascene::ProbeImageBytes(
      absl::string_view(reinterpret_cast<const char*>(data + 1), size - 1), name);
  if (header.ok() && (header->width <= 0 || header->height <= 0 ||
                      int64_t{header->width} * header->height > instascene::kMaxImagePixels)) {
    __builtin_trap();  // a header outside the limits must never be reported as fine
  }
  return 0;
}
