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
#include "services/generation/diffusion/onnx_denoiser.h"
#include "services/generation/diffusion/warping.h"

namespace instascene::generation::diffusion {
namespace {

// The camera of the latent grid: the view scaled to n x n.
PinholeCamera LatentCamera(const PinholeCamera& c, int n) {
  return c.Scaled(static_cast<double>(n) / c.width);
}

// A warp at image resolution brought to the n x n latent grid: a cell is known where more than
// half of its pixels are, and takes the mean of those pixels (mapped to [-1, 1]).
WarpResult EncodeWarp(const WarpResult& pixels, int width, int height, int n) {
  WarpResult cells;
  cells.values.assign(static_cast<size_t>(3) * n * n, 0.0f);
  cells.known.assign(static_cast<size_t>(n) * n, 0);
  std::vector<int> total(static_cast<size_t>(n) * n, 0), known(total.size(), 0);
  std::vector<double> sum(cells.values.size(), 0.0);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const size_t cell = static_cast<size_t>(y * n / height) * n + x * n / width;
      const size_t i = static_cast<size_t>(y) * width + x;
      ++total[cell];
      if (!pixels.known[i]) continue;
      ++known[cell];
      for (int c = 0; c < 3; ++c) sum[cell * 3 + c] += pixels.values[i * 3 + c];
    }
  }
  for (size_t cell = 0; cell < total.size(); ++cell) {
    if (2 * known[cell] <= total[cell]) continue;
    cells.known[cell] = 1;
    ++cells.written;
    for (int c = 0; c < 3; ++c)
      cells.values[cell * 3 + c] = static_cast<float>(2.0 * sum[cell * 3 + c] / known[cell] - 1.0);
  }
  return cells;
}

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

}  // namespace

DiffusionPrior::DiffusionPrior(std::shared_ptr<const Denoiser> denoiser, std::string where,
                               DiffusionPriorOptions options)
    : denoiser_(std::move(denoiser)), where_(std::move(where)), options_(options) {}

absl::StatusOr<PriorOutput> DiffusionPrior::Complete(const PriorInput& input) const {
  PriorOutput out;
  out.added.num_scales = 2;
  out.added.sh_degree = input.instance->sh_degree;
  if (input.targets.empty() || input.conditions.empty()) {
    out.abstained = true;
    out.reason = input.targets.empty() ? "no unknown ring view to generate"
                                       : "no known ring view to condition on";
    out.report = {{"denoiser", where_}};
    return out;
  }
  const int n = options_.latent_size;
  const std::shared_ptr<const LatentCodec> codec =
      options_.codec ? options_.codec : std::make_shared<IdentityCodec>(n);
  if (codec->latent_values() != 3 * n * n)
    return absl::InvalidArgumentError(absl::StrCat("diffusion prior: the codec ", codec->name(),
                                                   " makes latents of ", codec->latent_values(),
                                                   " values; the warping needs 3 x ", n, " x ", n));
  // Known views on the latent grid, and the mesh the warping casts against.
  const bool pixel_warp = options_.warp == "pixel";
  std::vector<KnownView> known;
  std::vector<std::vector<float>> condition_latents;
  for (const ViewImages& v : input.conditions) {
    ASSIGN_OR_RETURN(std::vector<float> latent,
                     codec->Encode(v.rgb, v.camera.width, v.camera.height));
    condition_latents.push_back(std::move(latent));
    if (pixel_warp) {  // the image itself, [0, 1], HxWx3
      known.push_back(KnownView{v.camera, v.rgb});
      continue;
    }
    // Warping copies latent values: store them HxWxC for the warper.
    KnownView k{LatentCamera(v.camera, n), std::vector<float>(static_cast<size_t>(3) * n * n)};
    for (int c = 0; c < 3; ++c) {
      for (int cell = 0; cell < n * n; ++cell)
        k.values[cell * 3 + c] = condition_latents.back()[c * n * n + cell];
    }
    known.push_back(std::move(k));
  }
  ASSIGN_OR_RETURN(std::unique_ptr<RayCaster> mesh,
                   RayCaster::Create(SurfelDiscs(*input.instance, {}, SurfelDiscOptions{})));
  std::vector<WarpResult> warped;
  int64_t warped_pixels = 0;
  for (const PinholeCamera& target : input.targets) {
    // Nearest known views first (by the angle between viewing directions).
    std::vector<KnownView> order = known;
    const Eigen::Vector3d dir_t = target.camera_from_world.rotation.row(2).transpose();
    std::stable_sort(order.begin(), order.end(), [&](const KnownView& a, const KnownView& b) {
      return a.camera.camera_from_world.rotation.row(2).dot(dir_t.transpose()) >
             b.camera.camera_from_world.rotation.row(2).dot(dir_t.transpose());
    });
    ASSIGN_OR_RETURN(
        WarpResult w,
        WarpIntoTarget(*mesh, order, pixel_warp ? target : LatentCamera(target, n), WarpOptions{}));
    if (pixel_warp) w = EncodeWarp(w, target.width, target.height, n);
    warped_pixels += w.written;
    warped.push_back(std::move(w));
  }
  RETURN_IF_ERROR(CheckCancelled(input.cancel, "diffusion prior"));
  const NoiseSchedule schedule = NoiseSchedule::ScaledLinear();
  DdimOptions ddim = options_.ddim;
  ddim.guidance = options_.guidance;
  ddim.seed = input.seed;
  std::vector<int> conditions(input.conditions.size());
  for (size_t k = 0; k < conditions.size(); ++k) conditions[k] = static_cast<int>(k);
  std::mt19937_64 replace_rng(input.seed ^ 0x5eedULL);
  std::normal_distribution<double> normal(0.0, 1.0);
  // RePaint: after each step, pixels a known view sees take the known latent noised to the
  // level the latents are now at (clean after the last step).
  // Replacement during the first replace_fraction of the steps (from the noisiest).
  const int replace_steps =
      static_cast<int>(std::ceil(options_.replace_fraction * ddim.steps - 1e-9));
  StepHook hook = [&](int step, int timestep,
                      std::vector<std::vector<float>>* latents) -> absl::Status {
    RETURN_IF_ERROR(CheckCancelled(input.cancel, "diffusion prior"));
    if (!options_.replace_known || step >= replace_steps) return absl::OkStatus();
    const double a = timestep < 0 ? 1.0 : schedule.alphas_cumprod[timestep];
    for (size_t t = 0; t < latents->size(); ++t) {
      for (int cell = 0; cell < n * n; ++cell) {
        if (!warped[t].known[cell]) continue;
        for (int c = 0; c < 3; ++c) {
          const double x0 = warped[t].values[cell * 3 + c];
          (*latents)[t][c * n * n + cell] =
              static_cast<float>(std::sqrt(a) * x0 + std::sqrt(1.0 - a) * normal(replace_rng));
        }
      }
    }
    return absl::OkStatus();
  };
  std::vector<PinholeCamera> condition_cameras;
  for (const ViewImages& v : input.conditions) condition_cameras.push_back(v.camera);
  const ConditionedDenoiser conditioned(*denoiser_, condition_latents, condition_cameras,
                                        input.targets);
  absl::StatusOr<std::vector<std::vector<float>>> latents =
      SampleDdim(conditioned, schedule, static_cast<int>(input.targets.size()), 3 * n * n,
                 conditions, ddim, hook);
  if (!latents.ok()) {
    return absl::Status(latents.status().code(), absl::StrCat("diffusion prior (denoiser ", where_,
                                                              "): ", latents.status().message()));
  }
  // How far the samples ended from the warped known content in the cells a known view sees (0
  // when replacement runs to the last step).
  double drift = 0;
  int64_t known_cells = 0;
  for (size_t t = 0; t < warped.size(); ++t) {
    for (int cell = 0; cell < n * n; ++cell) {
      if (!warped[t].known[cell]) continue;
      ++known_cells;
      for (int c = 0; c < 3; ++c)
        drift += std::abs((*latents)[t][c * n * n + cell] - warped[t].values[cell * 3 + c]) / 3;
    }
  }
  // Decode each target; the mask is where the image is not the ring's white background.
  for (size_t t = 0; t < input.targets.size(); ++t) {
    const PinholeCamera& cam = input.targets[t];
    ViewImages v;
    v.camera = cam;
    const size_t pixels = static_cast<size_t>(cam.width) * cam.height;
    ASSIGN_OR_RETURN(v.rgb, codec->Decode((*latents)[t], cam.width, cam.height));
    if (v.rgb.size() != 3 * pixels)
      return absl::InternalError(absl::StrCat("diffusion prior: the codec ", codec->name(),
                                              " decoded ", v.rgb.size(), " values for ", cam.width,
                                              "x", cam.height, "x3"));
    v.alpha.assign(pixels, 0.0f);
    v.mask.assign(pixels, 0);
    v.depth.assign(pixels, 0.0f);
    for (size_t i = 0; i < pixels; ++i) {
      const bool white =
          v.rgb[3 * i] > 0.98f && v.rgb[3 * i + 1] > 0.98f && v.rgb[3 * i + 2] > 0.98f;
      v.mask[i] = !white;
      v.alpha[i] = v.mask[i] ? 1.0f : 0.0f;
    }
    out.generated.push_back(std::move(v));
  }
  out.reason = absl::StrCat("generated ", input.targets.size(), " unknown views from ",
                            input.conditions.size(), " known ones");
  out.report = {{"denoiser", where_},
                {"latent_size", n},
                {"steps", ddim.steps},
                {"eta", ddim.eta},
                {"guidance", ddim.guidance},
                {"replace_known", options_.replace_known},
                {"replace_fraction", options_.replace_fraction},
                {"warp", options_.warp},
                {"warped_latent_pixels", warped_pixels},  // latent cells known, all targets
                {"known_cells_drift", known_cells ? drift / known_cells : 0.0},
                {"vae", codec->name()}};
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
  if (absl::StartsWith(denoiser, "grpc://")) {
    const std::string address = denoiser.substr(7);
    if (address.empty())
      return absl::InvalidArgumentError("--denoiser grpc://HOST:PORT: no address");
    GrpcDenoiserOptions options;
    options.latent_shape = {3, DiffusionPriorOptions{}.latent_size,
                            DiffusionPriorOptions{}.latent_size};
    auto client = std::make_shared<GrpcDenoiser>(rpc::Connect(address), address, options);
    return std::make_unique<DiffusionPrior>(client, denoiser, prior_options);
  }
  if (absl::StartsWith(denoiser, "onnx:")) {
    ASSIGN_OR_RETURN(OnnxDenoiserConfig config, ReadOnnxDenoiserConfig(denoiser.substr(5)));
    const std::vector<int>& shape = config.latent_shape;
    if (shape[0] != 3 || shape[1] != shape[2])
      return absl::InvalidArgumentError(
          absl::StrCat("ONNX denoiser ", config.name, ": latent_shape [", shape[0], ", ", shape[1],
                       ", ", shape[2],
                       "]; the diffusion prior's latents are [3, n, n] (the codec's channels on a "
                       "square grid)"));
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
