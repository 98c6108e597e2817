// libFuzzer harness: store manifests (what clients upload and workers read) on arbitrary bytes;
// a manifest that parses must serialise and parse back to itself.
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "common/store/manifest.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  absl::StatusOr<instascene::store::Manifest> m = instascene::store::ParseManifest(
      absl::string_view(reinterpret_cast<const char*>(data), size), "fuzz");
  if (!m.ok()) return 0;
  const std::string bytes = instascene::store::SerializeManifest(*m);
  absl::StatusOr<instascene::store::Manifest> again =
      instascene::store::ParseManifest(bytes, "fuzz (serialised)");
  if (!again.ok() || instascene::store::SerializeManifest(*again) != bytes) std::abort();
  return 0;
}
