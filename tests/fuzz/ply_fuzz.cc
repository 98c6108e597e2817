// libFuzzer harness: the PLY reader (header, every element's scalar columns) and the Gaussian-splat
// PLY loader on arbitrary bytes. Any crash, sanitizer report, or allocation past the input's bounds
// is a bug; errors are expected.
#include <cstddef>
#include <cstdint>

#include "common/splat/gaussian_ply.h"
#include "common/splat/ply.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const absl::string_view bytes(reinterpret_cast<const char*>(data), size);
  absl::StatusOr<instascene::PlyHeader> header = instascene::ParsePlyHeader(bytes, "fuzz.ply");
  if (header.ok()) {
    for (const instascene::PlyElement& element : header->elements)
      (void)instascene::ReadPlyElement(bytes, *header, element.name, "fuzz.ply");
  }
  (void)instascene::ParseGaussianPly(bytes, "fuzz.ply");
  return 0;
}
