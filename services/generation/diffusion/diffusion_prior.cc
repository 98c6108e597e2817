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
#include "services/generation/diffusion/unseen_region.h"
#include "services/generation/diffusion/warping.h"

namespace instascene::generation::diffusion {
namespace {

// The camera of the latent grid: the view scaled to n x n.
PinholeCamera LatentCamera(const PinholeCamera& c, int n) {
  return c.Scaled(static_cast<double>(n) / c.width);
}

// A warp at image resolution brought to the n x n latent grid: a cell is known where more than
// half of its pixels are, with the mean depth of those pixels; its latent is the codec's encoding
// of the warped image in which each unknown pixel takes its cell's known mean (white in cells
// with none), so that for the identity codec a known cell is exactly the mean of its known
// pixels.
absl::StatusOr<WarpResult> EncodeWarp(const WarpResult& pixels, const LatentCodec& codec, int width,
                                      int height, int n) {
  const int cells = n * n;
  WarpResult out;
  out.known.assign(cells, 0);
  out.depth.assign(cells, 0.0f);
  std::vector<int> total(cells, 0), known(cells, 0);
  std::vector<double> sum(static_cast<size_t>(3) * cells, 0.0), depth(cells, 0.0);
  auto cell_of = [&](int x, int y) {
    return static_cast<size_t>(y * n / height) * n + x * n / width;
  };
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const size_t cell = cell_of(x, y), i = static_cast<size_t>(y) * width + x;
      ++total[cell];
      if (!pixels.known[i]) continue;
      ++known[cell];
      depth[cell] += pixels.depth[i];
      for (int c = 0; c < 3; ++c) sum[cell * 3 + c] += pixels.values[i * 3 + c];
    }
  }
  std::vector<float> image(static_cast<size_t>(3) * width * height, 1.0f);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const size_t cell = cell_of(x, y), i = static_cast<size_t>(y) * width + x;
      for (int c = 0; c < 3; ++c) {
        image[i * 3 + c] = pixels.known[i]   ? pixels.values[i * 3 + c]
                           : known[cell] > 0 ? static_cast<float>(sum[cell * 3 + c] / known[cell])
                                             : 1.0f;
      }
    }
  }
  ASSIGN_OR_RETURN(const std::vector<float> latent, codec.Encode(image, width, height));
  const int channels = static_cast<int>(latent.size()) / cells;
  out.values.assign(latent.size(), 0.0f);
  for (int c = 0; c < channels; ++c) {
    for (int cell = 0; cell < cells; ++cell)
      out.values[cell * channels + c] = latent[c * cells + cell];
  }
  for (int cell = 0; cell < cells; ++cell) {
    if (2 * known[cell] <= total[cell]) continue;
    out.known[cell] = 1;
    ++out.written;
    out.depth[cell] = static_cast<float>(depth[cell] / known[cell]);
  }
  return out;
}

// The depth channel's code (DiffusionPriorOptions): z relative to the object centre's depth in
// units of the object's diameter, clamped to [-1, 1]; +1 is also the background.
struct DepthCode {
  double centre_z = 0, diameter = 1;
  DepthCode(const PinholeCamera& camera, const ObjectFrame& frame)
      : centre_z((camera.camera_from_world * frame.center.cast<double>()).z()),
        diameter(std::max(2.0 * frame.radius, 1e-9)) {}
  float Encode(double z) const {
    return static_cast<float>(std::clamp((z - centre_z) / diameter, -1.0, 1.0));
  }
  double Decode(float code) const { return centre_z + diameter * code; }
};

// The depth channel of a known view: per cell, the mean code of its masked pixels where most are
// masked, else the background.
std::vector<float> DepthChannel(const ViewImages& v, const ObjectFrame& frame, int n) {
  const DepthCode code(v.camera, frame);
  const int w = v.camera.width, h = v.camera.height;
  std::vector<double> sum(static_cast<size_t>(n) * n, 0.0);
  std::vector<int> total(sum.size(), 0), masked(sum.size(), 0);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t cell = static_cast<size_t>(y * n / h) * n + x * n / w;
      const size_t i = static_cast<size_t>(y) * w + x;
      ++total[cell];
      if (i >= v.mask.size() || !v.mask[i] || i >= v.depth.size() || !(v.depth[i] > 0)) continue;
      ++masked[cell];
      sum[cell] += code.Encode(v.depth[i]);
    }
  }
  std::vector<float> out(sum.size(), kBackgroundDepthCode);
  for (size_t cell = 0; cell < out.size(); ++cell) {
    if (2 * masked[cell] > total[cell]) out[cell] = static_cast<float>(sum[cell] / masked[cell]);
  }
  return out;
}

// z of the first instance hit of every pixel of `camera` (0 = miss).
std::vector<float> InstanceDepth(const RayCaster& mesh, const PinholeCamera& camera) {
  std::vector<float> depth(static_cast<size_t>(camera.width) * camera.height, 0.0f);
  const Eigen::Vector3f eye = camera.CenterInWorld().cast<float>();
  const Eigen::Vector3f axis = camera.camera_from_world.rotation.row(2).transpose().cast<float>();
  for (int row = 0; row < camera.height; ++row) {
    for (int col = 0; col < camera.width; ++col) {
      const Eigen::Vector3f dir = camera.PixelRayInWorld(col, row).cast<float>();
      const RayHit hit = mesh.Cast(eye, dir);
      if (hit.hit)
        depth[static_cast<size_t>(row) * camera.width + col] = hit.distance * dir.dot(axis);
    }
  }
  return depth;
}

// What the sampler is told about one target's latent cells: the warped known content (colour
// latent and depth code) and the cells pinned to the background.
struct TargetPlan {
  WarpResult warp;                  // on the latent grid
  std::vector<float> depth_code;    // n x n: the known cells' depth code (DepthCode)
  std::vector<uint8_t> background;  // n x n
  int64_t generated = 0;            // cells neither known nor background
};

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

// The codec's channels on an n x n grid (the identity's 3 when there is none).
int CodecChannels(const std::shared_ptr<const LatentCodec>& codec, int n) {
  return codec ? codec->latent_values() / (n * n) : 3;
}

// The known ring views as the sampler sees them: what the denoiser conditions on (colour latent
// + depth channel per view) and what the warper copies (the colour latent on the latent grid, or
// the image itself with a pixel warp).
struct KnownViews {
  std::vector<KnownView> warp_sources;
  std::vector<std::vector<float>> condition_latents;
};

absl::StatusOr<KnownViews> EncodeKnownViews(const PriorInput& input, const LatentCodec& codec,
                                            int n, int channels, bool pixel_warp) {
  const int cells = n * n;
  KnownViews out;
  for (const ViewImages& v : input.conditions) {
    ASSIGN_OR_RETURN(std::vector<float> latent,
                     codec.Encode(v.rgb, v.camera.width, v.camera.height));
    if (pixel_warp) {
      out.warp_sources.push_back(KnownView{v.camera, v.rgb});  // [0, 1], HxWx3
    } else {
      KnownView k{LatentCamera(v.camera, n),
                  std::vector<float>(static_cast<size_t>(channels) * cells)};
      for (int c = 0; c < channels; ++c) {
        for (int cell = 0; cell < cells; ++cell)
          k.values[cell * channels + c] = latent[c * cells + cell];
      }
      out.warp_sources.push_back(std::move(k));
    }
    const std::vector<float> depth = DepthChannel(v, input.frame, n);
    latent.insert(latent.end(), depth.begin(), depth.end());
    out.condition_latents.push_back(std::move(latent));
  }
  return out;
}

// One target view's plan: the known views warped into it (nearest first, by the angle between
// viewing directions), their depth codes, and with the unseen mask the cells pinned to the
// background (neither known, nor looking at unseen space, nor at the object).
absl::StatusOr<TargetPlan> PlanTarget(const PinholeCamera& target,
                                      const std::vector<KnownView>& known, const RayCaster& mesh,
                                      const LatentCodec& codec, const PriorInput& input, int n,
                                      int channels, bool pixel_warp, bool unseen_mask) {
  const int cells = n * n;
  std::vector<KnownView> order = known;
  const Eigen::Vector3d dir_t = target.camera_from_world.rotation.row(2).transpose();
  std::stable_sort(order.begin(), order.end(), [&](const KnownView& a, const KnownView& b) {
    return a.camera.camera_from_world.rotation.row(2).dot(dir_t.transpose()) >
           b.camera.camera_from_world.rotation.row(2).dot(dir_t.transpose());
  });
  const PinholeCamera grid = LatentCamera(target, n);
  TargetPlan plan;
  WarpOptions warp_options;
  warp_options.channels = pixel_warp ? 3 : channels;
  ASSIGN_OR_RETURN(plan.warp,
                   WarpIntoTarget(mesh, order, pixel_warp ? target : grid, warp_options));
  if (pixel_warp) {
    ASSIGN_OR_RETURN(plan.warp, EncodeWarp(plan.warp, codec, target.width, target.height, n));
  }
  const std::vector<float> hits = InstanceDepth(mesh, grid);
  const DepthCode code(target, input.frame);
  plan.depth_code.assign(cells, kBackgroundDepthCode);
  for (int cell = 0; cell < cells; ++cell) {
    if (plan.warp.known[cell]) plan.depth_code[cell] = code.Encode(plan.warp.depth[cell]);
  }
  plan.background.assign(cells, 0);
  if (unseen_mask) {
    const std::vector<uint8_t> unseen =
        UnseenRegion(*input.free_space, input.frame, grid, hits, target.width);
    for (int cell = 0; cell < cells; ++cell)
      plan.background[cell] = !plan.warp.known[cell] && !unseen[cell] && !(hits[cell] > 0);
  }
  for (int cell = 0; cell < cells; ++cell)
    plan.generated += !plan.warp.known[cell] && !plan.background[cell];
  return plan;
}

// The clean value of every pinned channel of a target's cell (colour latent, then depth code):
// the warped known content, or the background; false when the sampler generates the cell.
class PinnedCells {
 public:
  PinnedCells(const std::vector<TargetPlan>& plans, const std::vector<float>& background_latent,
              int channels, int cells)
      : plans_(plans), background_(background_latent), channels_(channels), cells_(cells) {}
  bool operator()(size_t t, int cell, float* x0) const {
    const TargetPlan& plan = plans_[t];
    if (plan.warp.known[cell]) {
      for (int c = 0; c < channels_; ++c) x0[c] = plan.warp.values[cell * channels_ + c];
      x0[channels_] = plan.depth_code[cell];
      return true;
    }
    if (!plan.background[cell]) return false;
    for (int c = 0; c < channels_; ++c) x0[c] = background_[c * cells_ + cell];
    x0[channels_] = kBackgroundDepthCode;
    return true;
  }

 private:
  const std::vector<TargetPlan>& plans_;
  const std::vector<float>& background_;
  int channels_, cells_;
};

// A sampled target latent decoded: colour through the codec; depth and mask from the depth
// channel (object pixels counted into `object_pixels`).
absl::StatusOr<ViewImages> DecodeTarget(const std::vector<float>& latent, const PinholeCamera& cam,
                                        const LatentCodec& codec, const ObjectFrame& frame, int n,
                                        int channels, int64_t* object_pixels) {
  const int cells = n * n;
  ViewImages v;
  v.camera = cam;
  const size_t pixels = static_cast<size_t>(cam.width) * cam.height;
  const std::vector<float> colour(latent.begin(), latent.begin() + channels * cells);
  ASSIGN_OR_RETURN(v.rgb, codec.Decode(colour, cam.width, cam.height));
  if (v.rgb.size() != 3 * pixels)
    return absl::InternalError(absl::StrCat("diffusion prior: the codec ", codec.name(),
                                            " decoded ", v.rgb.size(), " values for ", cam.width,
                                            "x", cam.height, "x3"));
  const DepthCode code(cam, frame);
  v.alpha.assign(pixels, 0.0f);
  v.mask.assign(pixels, 0);
  v.depth.assign(pixels, 0.0f);
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const size_t i = static_cast<size_t>(y) * cam.width + x;
      const float d = latent[channels * cells + (y * n / cam.height) * n + x * n / cam.width];
      if (!(d < kSurfaceDepthCode)) continue;
      v.mask[i] = 1;
      v.alpha[i] = 1.0f;
      v.depth[i] = static_cast<float>(std::max(code.Decode(d), 1e-6));
      ++*object_pixels;
    }
  }
  return v;
}

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
  const int n = options_.latent_size, cells = n * n;
  const std::shared_ptr<const LatentCodec> codec =
      options_.codec ? options_.codec : std::make_shared<IdentityCodec>(n);
  const int channels = codec->latent_values() / cells;  // the codec's (VAE's) channels
  if (channels < 1 || channels > kMaxCodecChannels || codec->latent_values() != channels * cells)
    return absl::InvalidArgumentError(absl::StrCat(
        "diffusion prior: the codec ", codec->name(), " makes latents of ", codec->latent_values(),
        " values; the warping needs C x ", n, " x ", n, " with C in [1, ", kMaxCodecChannels, "]"));
  const int latent_values = (channels + 1) * cells;  // colour latent + depth channel
  const bool pixel_warp = options_.warp == "pixel";
  ASSIGN_OR_RETURN(const KnownViews known,
                   EncodeKnownViews(input, *codec, n, channels, pixel_warp));
  ASSIGN_OR_RETURN(
      const std::vector<float> background_latent,
      codec->Encode(
          std::vector<float>(
              static_cast<size_t>(3) * input.targets[0].width * input.targets[0].height, 1.0f),
          input.targets[0].width, input.targets[0].height));
  ASSIGN_OR_RETURN(std::unique_ptr<RayCaster> mesh,
                   RayCaster::Create(SurfelDiscs(*input.instance, {}, SurfelDiscOptions{})));
  const bool unseen_mask = options_.unseen_mask && input.free_space != nullptr;
  std::vector<TargetPlan> plans;
  int64_t warped_cells = 0, background_cells = 0, generated_cells = 0;
  for (const PinholeCamera& target : input.targets) {
    ASSIGN_OR_RETURN(TargetPlan plan, PlanTarget(target, known.warp_sources, *mesh, *codec, input,
                                                 n, channels, pixel_warp, unseen_mask));
    for (int cell = 0; cell < cells; ++cell) background_cells += plan.background[cell];
    warped_cells += plan.warp.written;
    generated_cells += plan.generated;
    plans.push_back(std::move(plan));
  }
  RETURN_IF_ERROR(CheckCancelled(input.cancel, "diffusion prior"));
  const NoiseSchedule schedule = NoiseSchedule::ScaledLinear();
  DdimOptions ddim = options_.ddim;
  ddim.guidance = options_.guidance;
  ddim.seed = input.seed;
  std::vector<int> conditions(input.conditions.size());
  for (size_t k = 0; k < conditions.size(); ++k) conditions[k] = static_cast<int>(k);
  const PinnedCells pinned(plans, background_latent, channels, cells);
  std::mt19937_64 replace_rng(input.seed ^ 0x5eedULL);
  std::normal_distribution<double> normal(0.0, 1.0);
  // RePaint: after each step of the first replace_fraction of the steps (from the noisiest),
  // pinned cells take their clean value noised to the level the latents are now at (clean after
  // the last step).
  const int replace_steps =
      static_cast<int>(std::ceil(options_.replace_fraction * ddim.steps - 1e-9));
  StepHook hook = [&](int step, int timestep,
                      std::vector<std::vector<float>>* latents) -> absl::Status {
    RETURN_IF_ERROR(CheckCancelled(input.cancel, "diffusion prior"));
    if (!options_.replace_known || step >= replace_steps) return absl::OkStatus();
    const double a = timestep < 0 ? 1.0 : schedule.alphas_cumprod[timestep];
    for (size_t t = 0; t < latents->size(); ++t) {
      for (int cell = 0; cell < cells; ++cell) {
        float x0[kMaxCodecChannels + 1];
        if (!pinned(t, cell, x0)) continue;
        for (int c = 0; c <= channels; ++c) {
          (*latents)[t][c * cells + cell] =
              static_cast<float>(std::sqrt(a) * x0[c] + std::sqrt(1.0 - a) * normal(replace_rng));
        }
      }
    }
    return absl::OkStatus();
  };
  std::vector<PinholeCamera> condition_cameras;
  for (const ViewImages& v : input.conditions) condition_cameras.push_back(v.camera);
  const ConditionedDenoiser conditioned(*denoiser_, known.condition_latents, condition_cameras,
                                        input.targets);
  absl::StatusOr<std::vector<std::vector<float>>> latents =
      SampleDdim(conditioned, schedule, static_cast<int>(input.targets.size()), latent_values,
                 conditions, ddim, hook);
  if (!latents.ok()) {
    return absl::Status(latents.status().code(), absl::StrCat("diffusion prior (denoiser ", where_,
                                                              "): ", latents.status().message()));
  }
  // How far the samples ended from the warped known content in the cells a known view sees (0
  // when replacement runs to the last step), over the colour and depth channels.
  double drift = 0;
  int64_t known_cells = 0;
  for (size_t t = 0; t < plans.size(); ++t) {
    for (int cell = 0; cell < cells; ++cell) {
      float x0[kMaxCodecChannels + 1];
      if (!plans[t].warp.known[cell] || !pinned(t, cell, x0)) continue;
      ++known_cells;
      for (int c = 0; c <= channels; ++c)
        drift += std::abs((*latents)[t][c * cells + cell] - x0[c]) / (channels + 1);
    }
  }
  int64_t object_pixels = 0;
  for (size_t t = 0; t < input.targets.size(); ++t) {
    ASSIGN_OR_RETURN(ViewImages v, DecodeTarget((*latents)[t], input.targets[t], *codec,
                                                input.frame, n, channels, &object_pixels));
    out.generated.push_back(std::move(v));
  }
  out.reason = absl::StrCat("generated ", input.targets.size(), " unknown views from ",
                            input.conditions.size(), " known ones");
  out.report = {{"denoiser", where_},
                {"latent_size", n},
                {"latent_shape", {channels + 1, n, n}},
                {"steps", ddim.steps},
                {"eta", ddim.eta},
                {"guidance", ddim.guidance},
                {"replace_known", options_.replace_known},
                {"replace_fraction", options_.replace_fraction},
                {"warp", options_.warp},
                {"unseen_mask", unseen_mask},
                {"warped_latent_pixels", warped_cells},  // latent cells known, all targets
                {"background_cells", background_cells},  // pinned to the background
                {"generated_cells", generated_cells},    // left to the sampler
                {"generated_object_pixels", object_pixels},
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
