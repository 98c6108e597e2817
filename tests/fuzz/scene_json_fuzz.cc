// libFuzzer harness: scene.json (the upload format's index) on arbitrary text.
#include <cstddef>
#include <cstdint>

#include "common/scene/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  (void)instascene::ParseSceneJson(absl::string_view(reinterpret_cast<const char*>(data), size),
                                   "fuzz/scene.json");
  return 0;
}
