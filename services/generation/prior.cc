#include "services/generation/prior.h"

#include "absl/strings/str_cat.h"
#include "services/generation/diffusion/diffusion_prior.h"
#include "services/generation/geometric_prior.h"

namespace instascene::generation {

absl::StatusOr<std::unique_ptr<CompletionPrior>> MakePrior(const std::string& name,
                                                           const std::string& denoiser,
                                                           const DiffusionSettings& diffusion,
                                                           const GeometricPriorOptions* geometric) {
  if (name == "geometric") {
    return std::make_unique<GeometricPrior>(geometric != nullptr ? *geometric
                                                                 : GeometricPriorOptions{});
  }
  if (name == "none") return std::make_unique<NoPrior>();
  if (name == "diffusion") return diffusion::MakeDiffusionPrior(denoiser, diffusion);
  return absl::InvalidArgumentError(
      absl::StrCat("unknown completion prior '", name, "' (known: geometric, none, diffusion)"));
}

}  // namespace instascene::generation
