// libFuzzer harness: every shipped stage's parameter codec (what SubmitPipeline validates) on
// arbitrary JSON. The first byte picks the stage; canonical parameters must canonicalise to
// themselves (the job key depends on it).
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include <nlohmann/json.hpp>

#include "services/pipeline/registry.h"
#include "services/stages/all_stages.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const instascene::pipeline::StageRegistry* registry = [] {
    auto* r = new instascene::pipeline::StageRegistry();
    if (!instascene::stages::RegisterStageSpecs(r).ok()) std::abort();
    return r;
  }();
  if (size == 0) return 0;
  const std::vector<std::string> kinds = registry->Kinds();
  const std::string& kind = kinds[data[0] % kinds.size()];
  const nlohmann::json parameters =
      nlohmann::json::parse(reinterpret_cast<const char*>(data) + 1,
                            reinterpret_cast<const char*>(data) + size, nullptr, false);
  if (parameters.is_discarded()) return 0;
  absl::StatusOr<nlohmann::json> canonical = registry->Canonicalize(kind, parameters);
  if (!canonical.ok()) return 0;
  absl::StatusOr<nlohmann::json> again = registry->Canonicalize(kind, *canonical);
  if (!again.ok() || *again != *canonical) std::abort();
  return 0;
}
