#include "services/generation/diffusion/diffusion_prior.h"

#include <algorithm>
#include <cmath>
#include <random>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/mesh/ray_caster.h"
#include "common/mesh/surfel_mesh.h"
#include "common/rpc/server.h"
#include "services/generation/diffusion/grpc_denoiser.h"
#include "services/generation/diffusion/latent_codec.h"
#include "services/generation/diffusion/latent_views.h"
#include "services/generation/diffusion/onnx_denoiser.h"
#include "services/generation/diffusion/warping.h"

namespace instascene::generation::diffusion {
namespace {

// The prior's denoiser with what a real model conditions on filled into each conditional query:
// the condition view's clean latent and the target camera relative to the condition camera.
class ConditionedDenoiser : public Denoiser {
 public:
  ConditionedDenoiser(const Denoiser& inner, const std::vector<std::vector<float>>& latents,
                      const std::vector<PinholeCamera>& conditions,
                      const std::vector<PinholeCamera>& targets)
      : inner_(inner), latents_(latents), poses_(targets.size()) {
    for (size_t t = 0; t < targets.size(); ++t) {
      for (const PinholeCamera& c : conditions) {
        const Rigid3d rel = targets[t].camera_from_world * c.camera_from_world.Inverse();
        std::array<double, 16> m{};
        for (int r = 0; r < 3; ++r) {
          for (int k = 0; k < 3; ++k) m[4 * r + k] = rel.rotation(r, k);
          m[4 * r + 3] = rel.translation[r];
        }
        m[15] = 1.0;
        poses_[t].push_back(m);
      }
    }
  }
  absl::StatusOr<std::vector<float>> PredictNoise(const NoiseQuery& query) const override {
    NoiseQuery q = query;
    if (q.condition >= 0 && q.condition < static_cast<int>(latents_.size()) && q.target >= 0 &&
        q.target < static_cast<int>(poses_.size())) {
      q.condition_latent = &latents_[q.condition];
      q.target_from_condition = &poses_[q.target][q.condition];
    }
    return inner_.PredictNoise(q);
  }

 private:
  const Denoiser& inner_;
  const std::vector<std::vector<float>>& latents_;
  std::vector<std::vector<std::array<double, 16>>> poses_;
};

// The codec's (VAE's) latent channels C: InvalidArgument unless its latents are C x n x n with C
// in [1, kMaxCodecChannels] (what the warping handles).
absl::StatusOr<int> CodecChannels(const LatentCodec& codec, int n) {
  const int cells = n * n;
  const int channels = codec.latent_values() / cells;
  if (channels < 1 || channels > kMaxCodecChannels || codec.latent_values() != channels * cells)
    return absl::InvalidArgumentError(absl::StrCat(
        "diffusion prior: the codec ", codec.name(), " makes latents of ", codec.latent_values(),
        " values; the warping needs C x ", n, " x ", n, " with C in [1, ", kMaxCodecChannels, "]"));
  return channels;
}

// Every target's plan on the latent grid (what the known views show of it, warped through the
// instance's surfel discs; what stays background; what is left to the sampler), with the counts
// the report gives.
struct PlannedTargets {
  std::vector<TargetPlan> plans;
  int64_t warped_cells = 0, background_cells = 0, generated_cells = 0;
};
absl::StatusOr<PlannedTargets> PlanTargets(const PriorInput& input, const KnownViews& known,
                                           const LatentCodec& codec, int n, int channels,
                                           bool pixel_warp, bool unseen_mask) {
  ASSIGN_OR_RETURN(std::unique_ptr<RayCaster> mesh,
                   RayCaster::Create(SurfelDiscs(*input.instance, {}, SurfelDiscOptions{})));
  PlannedTargets out;
  for (const PinholeCamera& target : input.targets) {
    ASSIGN_OR_RETURN(TargetPlan plan, PlanTarget(target, known.warp_sources, *mesh, codec, input, n,
                                                 channels, pixel_warp, unseen_mask));
    for (int cell = 0; cell < n * n; ++cell) out.background_cells += plan.background[cell];
    out.warped_cells += plan.warp.written;
    out.generated_cells += plan.generated;
    out.plans.push_back(std::move(plan));
  }
  return out;
}

// RePaint: after each step of the first `replace_fraction` of the steps (from the noisiest),
// pinned cells take their clean value noised to the level the latents are now at (clean after
// the last step). Checks for cancellation at every step.
StepHook RepaintHook(const PinnedCells& pinned, const NoiseSchedule& schedule,
                     const DiffusionPriorOptions& options, int steps, int channels, int cells,
                     uint64_t seed, const CancelFlag* cancel) {
  const int replace_steps = static_cast<int>(std::ceil(options.replace_fraction * steps - 1e-9));
  struct Noise {
    std::mt19937_64 rng;
    std::normal_distribution<double> normal{0.0, 1.0};
  };
  auto noise = std::make_shared<Noise>(Noise{std::mt19937_64(seed ^ 0x5eedULL)});
  return
      [&pinned, &schedule, replace = options.replace_known, replace_steps, channels, cells, cancel,
       noise](int step, int timestep, std::vector<std::vector<float>>* latents) -> absl::Status {
        RETURN_IF_ERROR(CheckCancelled(cancel, "diffusion prior"));
        if (!replace || step >= replace_steps) return absl::OkStatus();
        const double a = timestep < 0 ? 1.0 : schedule.alphas_cumprod[timestep];
        for (size_t t = 0; t < latents->size(); ++t) {
          for (int cell = 0; cell < cells; ++cell) {
            float x0[kMaxCodecChannels + 1];
            if (!pinned(t, cell, x0)) continue;
            for (int c = 0; c <= channels; ++c) {
              (*latents)[t][c * cells + cell] = static_cast<float>(
                  std::sqrt(a) * x0[c] + std::sqrt(1.0 - a) * noise->normal(noise->rng));
            }
          }
        }
        return absl::OkStatus();
      };
}

// How far the samples ended from the warped known content in the cells a known view sees (0
// when replacement runs to the last step), per cell over the colour and depth channels.
double KnownCellsDrift(const std::vector<TargetPlan>& plans, const PinnedCells& pinned,
                       const std::vector<std::vector<float>>& latents, int channels, int cells) {
  double drift = 0;
  int64_t known_cells = 0;
  for (size_t t = 0; t < plans.size(); ++t) {
    for (int cell = 0; cell < cells; ++cell) {
      float x0[kMaxCodecChannels + 1];
      if (!plans[t].warp.known[cell] || !pinned(t, cell, x0)) continue;
      ++known_cells;
      for (int c = 0; c <= channels; ++c)
        drift += std::abs(latents[t][c * cells + cell] - x0[c]) / (channels + 1);
    }
  }
  return known_cells ? drift / known_cells : 0.0;
}

// A codec latent of a white (background) target image.
absl::StatusOr<std::vector<float>> BackgroundLatent(const LatentCodec& codec,
                                                    const PinholeCamera& target) {
  return codec.Encode(
      std::vector<float>(static_cast<size_t>(3) * target.width * target.height, 1.0f), target.width,
      target.height);
}

// DDIM sampling of every target's latent (colour channels + depth), conditioned on the known
// views' latents, with the known cells replaced while `replace_fraction` of the steps run.
absl::StatusOr<std::vector<std::vector<float>>> SampleTargets(
    const Denoiser& denoiser, const std::string& where, const DiffusionPriorOptions& options,
    const DdimOptions& ddim, const PriorInput& input, const KnownViews& known,
    const PinnedCells& pinned, int channels, int cells) {
  const NoiseSchedule schedule = NoiseSchedule::ScaledLinear();
  std::vector<int> conditions(input.conditions.size());
  for (size_t k = 0; k < conditions.size(); ++k) conditions[k] = static_cast<int>(k);
  const StepHook hook =
      RepaintHook(pinned, schedule, options, ddim.steps, channels, cells, input.seed, input.cancel);
  std::vector<PinholeCamera> condition_cameras;
  for (const ViewImages& v : input.conditions) condition_cameras.push_back(v.camera);
  const ConditionedDenoiser conditioned(denoiser, known.condition_latents, condition_cameras,
                                        input.targets);
  absl::StatusOr<std::vector<std::vector<float>>> latents =
      SampleDdim(conditioned, schedule, static_cast<int>(input.targets.size()),
                 (channels + 1) * cells, conditions, ddim, hook);
  if (!latents.ok()) {
    return absl::Status(latents.status().code(), absl::StrCat("diffusion prior (denoiser ", where,
                                                              "): ", latents.status().message()));
  }
  return latents;
}

// Nothing to generate (no unknown ring view) or nothing to condition on (no known one).
PriorOutput Abstain(const PriorInput& input, const std::string& where, PriorOutput out) {
  out.abstained = true;
  out.reason = input.targets.empty() ? "no unknown ring view to generate"
                                     : "no known ring view to condition on";
  out.report = {{"denoiser", where}};
  return out;
}

// What the sampler did, for the completion's manifest: its settings and how many latent cells
// were known (warped), pinned to the background or generated.
nlohmann::json SamplingReport(const std::string& where, const DiffusionPriorOptions& options,
                              const DdimOptions& ddim, int channels, bool unseen_mask,
                              const PlannedTargets& planned, int64_t object_pixels, double drift,
                              const LatentCodec& codec) {
  return {{"denoiser", where},
          {"latent_size", options.latent_size},
          {"latent_shape", {channels + 1, options.latent_size, options.latent_size}},
          {"steps", ddim.steps},
          {"eta", ddim.eta},
          {"guidance", ddim.guidance},
          {"replace_known", options.replace_known},
          {"replace_fraction", options.replace_fraction},
          {"warp", options.warp},
          {"unseen_mask", unseen_mask},
          {"warped_latent_pixels", planned.warped_cells},  // latent cells known, all targets
          {"background_cells", planned.background_cells},  // pinned to the background
          {"generated_cells", planned.generated_cells},    // left to the sampler
          {"generated_object_pixels", object_pixels},
          {"known_cells_drift", drift},
          {"vae", codec.name()}};
}

}  // namespace

DiffusionPrior::DiffusionPrior(std::shared_ptr<const Denoiser> denoiser, std::string where,
                               DiffusionPriorOptions options)
    : denoiser_(std::move(denoiser)), where_(std::move(where)), options_(options) {}

absl::StatusOr<PriorOutput> DiffusionPrior::Complete(const PriorInput& input) const {
  PriorOutput out;
  out.added.num_scales = 2;
  out.added.sh_degree = input.instance->sh_degree;
  if (input.targets.empty() || input.conditions.empty()) return Abstain(input, where_, out);
  const int n = options_.latent_size, cells = n * n;
  const std::shared_ptr<const LatentCodec> codec =
      options_.codec ? options_.codec : std::make_shared<IdentityCodec>(n);
  ASSIGN_OR_RETURN(const int channels, CodecChannels(*codec, n));
  const bool pixel_warp = options_.warp == "pixel";
  ASSIGN_OR_RETURN(const KnownViews known,
                   EncodeKnownViews(input, *codec, n, channels, pixel_warp));
  ASSIGN_OR_RETURN(const std::vector<float> background_latent,
                   BackgroundLatent(*codec, input.targets[0]));
  const bool unseen_mask = options_.unseen_mask && input.free_space != nullptr;
  ASSIGN_OR_RETURN(const PlannedTargets planned,
                   PlanTargets(input, known, *codec, n, channels, pixel_warp, unseen_mask));
  const std::vector<TargetPlan>& plans = planned.plans;
  RETURN_IF_ERROR(CheckCancelled(input.cancel, "diffusion prior"));
  DdimOptions ddim = options_.ddim;
  ddim.guidance = options_.guidance;
  ddim.seed = input.seed;
  const PinnedCells pinned(plans, background_latent, channels, cells);
  ASSIGN_OR_RETURN(
      const std::vector<std::vector<float>> latents,
      SampleTargets(*denoiser_, where_, options_, ddim, input, known, pinned, channels, cells));
  const double drift = KnownCellsDrift(plans, pinned, latents, channels, cells);
  int64_t object_pixels = 0;
  for (size_t t = 0; t < input.targets.size(); ++t) {
    ASSIGN_OR_RETURN(ViewImages v, DecodeTarget(latents[t], input.targets[t], *codec, input.frame,
                                                n, channels, &object_pixels));
    out.generated.push_back(std::move(v));
  }
  out.reason = absl::StrCat("generated ", input.targets.size(), " unknown views from ",
                            input.conditions.size(), " known ones");
  out.report = SamplingReport(where_, options_, ddim, channels, unseen_mask, planned, object_pixels,
                              drift, *codec);
  return out;
}

absl::StatusOr<std::unique_ptr<CompletionPrior>> MakeDiffusionPrior(
    const std::string& denoiser, const DiffusionSettings& settings) {
  DiffusionPriorOptions prior_options;
  if (!(settings.replace_fraction >= 0 && settings.replace_fraction <= 1))
    return absl::InvalidArgumentError("diffusion replace_fraction must be in [0, 1]");
  if (settings.warp != "latent" && settings.warp != "pixel")
    return absl::InvalidArgumentError(
        absl::StrCat("diffusion warp '", settings.warp.substr(0, 40), "': latent or pixel"));
  prior_options.replace_fraction = settings.replace_fraction;
  prior_options.warp = settings.warp;
  prior_options.codec = settings.codec;
  prior_options.unseen_mask = settings.unseen_mask;
  if (absl::StartsWith(denoiser, "grpc://")) {
    const std::string address = denoiser.substr(7);
    if (address.empty())
      return absl::InvalidArgumentError("--denoiser grpc://HOST:PORT: no address");
    GrpcDenoiserOptions options;
    const int n = prior_options.latent_size;
    options.latent_shape = {CodecChannels(settings.codec, n) + 1, n, n};
    auto client = std::make_shared<GrpcDenoiser>(rpc::Connect(address), address, options);
    return std::make_unique<DiffusionPrior>(client, denoiser, prior_options);
  }
  if (absl::StartsWith(denoiser, "onnx:")) {
    ASSIGN_OR_RETURN(OnnxDenoiserConfig config, ReadOnnxDenoiserConfig(denoiser.substr(5)));
    const std::vector<int>& shape = config.latent_shape;
    const int channels = CodecChannels(settings.codec, shape[1]);
    if (shape[0] != channels + 1 || shape[1] != shape[2])
      return absl::InvalidArgumentError(absl::StrCat(
          "ONNX denoiser ", config.name, ": latent_shape [", shape[0], ", ", shape[1], ", ",
          shape[2], "]; the diffusion prior's latents are [", channels + 1, ", n, n] (the codec's ",
          channels, " channels and a depth channel on a square grid)"));
    prior_options.latent_size = shape[1];
    ASSIGN_OR_RETURN(std::unique_ptr<OnnxDenoiser> model,
                     OnnxDenoiser::Load(std::move(config), NoiseSchedule::ScaledLinear()));
    return std::make_unique<DiffusionPrior>(std::shared_ptr<const Denoiser>(std::move(model)),
                                            denoiser, prior_options);
  }
  return absl::InvalidArgumentError(
      absl::StrCat("the diffusion prior needs --denoiser grpc://HOST:PORT (a Denoiser service) or "
                   "onnx:FILE.json (an ONNX model), not '",
                   denoiser.substr(0, 80), "'"));
}

}  // namespace instascene::generation::diffusion
