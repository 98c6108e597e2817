#include "common/raster/surfel_backward.h"

#include <tbb/parallel_for.h>
#include <unsupported/Eigen/AutoDiff>

#include <algorithm>
#include <cmath>
#include <numeric>

#include "absl/strings/str_cat.h"
#include "common/raster/surfel_model.h"

namespace instascene {
namespace {

using surfel_model::Camera;
using surfel_model::Colour;
using surfel_model::Deriv;
using surfel_model::Dual;
using surfel_model::kAlphaMaxD;
using surfel_model::kAlphaMinD;
using surfel_model::kTMin;
using surfel_model::MakeCamera;
using surfel_model::Plain;
using surfel_model::Project;
using surfel_model::RawAlpha;
using surfel_model::Seeded;
using surfel_model::Splat;
using surfel_model::SurfelColour;

absl::Status Check(const GaussianCloud& cloud, const PinholeCamera& camera) {
  if (cloud.num_scales != 2) return absl::InvalidArgumentError("differentiable render: needs 2DGS");
  if (cloud.sh_degree > 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("differentiable render: SH degree ", cloud.sh_degree, " > 1"));
  }
  return camera.Validate();
}

// The per-view state shared by forward and backward: projected splats and colours in depth order.
struct Prepared {
  Camera cam;
  std::vector<uint32_t> order;  // visible surfels, front to back (depth, then index)
  std::vector<Splat<double>> splats;
  std::vector<Colour> colours;
  std::vector<Eigen::Vector4i> boxes;  // x0, x1, y0, y1: pixels where alpha >= 1/255 is possible
  bool cutoffs = true;
  // Per 16x16 tile, the surfels whose box touches it, front to back (a subsequence of `order`).
  int tiles_x = 0;
  std::vector<std::vector<uint32_t>> tiles;
};

constexpr int kTile = 16;

Prepared Prepare(const GaussianCloud& cloud, const PinholeCamera& camera,
                 const SurfelRenderOptions& options) {
  Prepared p;
  p.cam = MakeCamera(camera, options.near_plane);
  p.cutoffs = options.cutoffs;
  p.splats.resize(cloud.size());
  p.colours.resize(cloud.size());
  p.boxes.resize(cloud.size());
  for (uint32_t g = 0; g < cloud.size(); ++g) {
    const Splat<double> sp = Project(Plain(cloud, g), p.cam);
    if (!(sp.depth > options.near_plane)) continue;
    p.splats[g] = sp;
    p.colours[g] = SurfelColour(cloud, g, p.cam);
    // Conservative pixel box: 3 sigma of the larger axis at the centre's depth, plus the 2D
    // filter's reach (rho2d <= 2 ln(255 opacity) at sqrt(ln(255 opacity)) px).
    const double sigma_px =
        std::max(camera.fx, camera.fy) *
        std::exp(std::max(cloud.log_scales[2 * g], cloud.log_scales[2 * g + 1])) / sp.depth;
    // Without cut-offs every pixel counts.
    const double reach = options.cutoffs ? 4.0 * sigma_px + 3.0 : 1e9;
    p.boxes[g] = Eigen::Vector4i(
        static_cast<int>(std::clamp(std::floor(sp.proj_x - reach), 0.0, 1.0 * camera.width)),
        static_cast<int>(std::clamp(std::ceil(sp.proj_x + reach) + 1, 0.0, 1.0 * camera.width)),
        static_cast<int>(std::clamp(std::floor(sp.proj_y - reach), 0.0, 1.0 * camera.height)),
        static_cast<int>(std::clamp(std::ceil(sp.proj_y + reach) + 1, 0.0, 1.0 * camera.height)));
    if (p.boxes[g][0] >= p.boxes[g][1] || p.boxes[g][2] >= p.boxes[g][3]) continue;
    p.order.push_back(g);
  }
  std::stable_sort(p.order.begin(), p.order.end(),
                   [&](uint32_t a, uint32_t b) { return p.splats[a].depth < p.splats[b].depth; });
  p.tiles_x = (camera.width + kTile - 1) / kTile;
  const int tiles_y = (camera.height + kTile - 1) / kTile;
  p.tiles.resize(static_cast<size_t>(p.tiles_x) * tiles_y);
  for (uint32_t g : p.order) {
    const Eigen::Vector4i& b = p.boxes[g];
    for (int ty = b[2] / kTile; ty <= (b[3] - 1) / kTile; ++ty) {
      for (int tx = b[0] / kTile; tx <= (b[1] - 1) / kTile; ++tx) {
        p.tiles[static_cast<size_t>(ty) * p.tiles_x + tx].push_back(g);
      }
    }
  }
  return p;
}

// One pixel's contributors, front to back: (surfel, alpha, transmittance before it).
struct Contributor {
  uint32_t g;
  double alpha, raw_alpha, T;
};

double BlendPixel(const Prepared& p, int x, int y, std::vector<Contributor>* list) {
  list->clear();
  double T = 1.0;
  for (uint32_t g : p.tiles[static_cast<size_t>(y / kTile) * p.tiles_x + x / kTile]) {
    const Eigen::Vector4i& box = p.boxes[g];
    if (x < box[0] || x >= box[1] || y < box[2] || y >= box[3]) continue;
    const double raw = RawAlpha(p.splats[g], x, y, p.cam.near_plane);
    const double alpha = std::min(kAlphaMaxD, raw);
    if (p.cutoffs && alpha < kAlphaMinD) continue;
    const double next_T = T * (1.0 - alpha);
    if (p.cutoffs && next_T < kTMin) break;
    list->push_back({g, alpha, raw, T});
    T = next_T;
  }
  return T;
}

// The gradients that one band of 16 image rows sends to the surfels it touches.
struct BandGradients {
  std::vector<uint32_t> touched;
  std::vector<Deriv> geometry;          // parallel to touched
  std::vector<Eigen::Vector3d> colour;  // parallel to touched
};

BandGradients BackwardBand(const GaussianCloud& cloud, const PinholeCamera& camera,
                           const SurfelRenderOptions& options, const Prepared& p,
                           const std::vector<float>& dloss_dcolor,
                           const std::vector<float>& dloss_dalpha, int band) {
  BandGradients out;
  std::vector<int32_t> slot(cloud.size(), -1);
  auto at = [&](uint32_t g) {
    if (slot[g] < 0) {
      slot[g] = static_cast<int32_t>(out.touched.size());
      out.touched.push_back(g);
      out.geometry.push_back(Deriv::Zero());
      out.colour.push_back(Eigen::Vector3d::Zero());
    }
    return slot[g];
  };
  std::vector<Contributor> list;
  for (int y = band * kTile; y < std::min(camera.height, (band + 1) * kTile); ++y) {
    for (int x = 0; x < camera.width; ++x) {
      const double T_final = BlendPixel(p, x, y, &list);
      const size_t i = static_cast<size_t>(y) * camera.width + x;
      const Eigen::Vector3d dc(dloss_dcolor[3 * i], dloss_dcolor[3 * i + 1],
                               dloss_dcolor[3 * i + 2]);
      const double da = dloss_dalpha.empty() ? 0.0 : dloss_dalpha[i];
      // Back to front: "after" = what lies behind contributor k (colour incl. background).
      Eigen::Vector3d after =
          T_final *
          Eigen::Vector3d(options.background[0], options.background[1], options.background[2]);
      for (auto it = list.rbegin(); it != list.rend(); ++it) {
        const Contributor& k = *it;
        const Eigen::Vector3d& c = p.colours[k.g].rgb;
        const int s = at(k.g);
        out.colour[s] += k.alpha * k.T * dc;
        // C = sum c_j a_j T_j + T_N bg: dC/da_k = c_k T_k - after_k / (1 - a_k);
        // A = 1 - T_N: dA/da_k = T_N / (1 - a_k).
        const double dL_dalpha =
            dc.dot(c * k.T - after / (1.0 - k.alpha)) + da * (T_final / (1.0 - k.alpha));
        after += k.alpha * k.T * c;
        if (k.raw_alpha < kAlphaMaxD) {  // the 0.99 clamp passes no gradient
          const Dual a = RawAlpha(Project(Seeded(cloud, k.g), p.cam), x, y, p.cam.near_plane);
          out.geometry[s] += dL_dalpha * a.derivatives();
        }
      }
    }
  }
  return out;
}

// The summed gradients per surfel (geometry; colour, back through the clamp and the view-dependent
// colour's SH basis) as gradients of the cloud's parameters.
SurfelGradients ParameterGradients(const GaussianCloud& cloud, const Prepared& p,
                                   const std::vector<Deriv>& d_geometry,
                                   const std::vector<Eigen::Vector3d>& d_colour) {
  SurfelGradients out = SurfelGradients::Zeros(cloud);
  const int stride = cloud.sh_stride();
  const int coeffs = cloud.sh_degree == 0 ? 1 : 4;
  for (size_t g = 0; g < cloud.size(); ++g) {
    const Deriv& d = d_geometry[g];
    const Colour& colour = p.colours[g];
    Eigen::Vector3d d_rgb = d_colour[g];
    for (int c = 0; c < 3; ++c) {
      if (colour.clamped[c]) d_rgb[c] = 0;
    }
    const Eigen::Vector3d d_pos = d.segment<3>(0) + colour.d_position.transpose() * d_rgb;
    for (int k = 0; k < 3; ++k) out.positions[3 * g + k] = static_cast<float>(d_pos[k]);
    for (int k = 0; k < 2; ++k) out.log_scales[2 * g + k] = static_cast<float>(d[3 + k]);
    for (int k = 0; k < 4; ++k) out.rotations[4 * g + k] = static_cast<float>(d[5 + k]);
    out.opacity_logits[g] = static_cast<float>(d[9]);
    for (int k = 0; k < coeffs; ++k) {
      for (int c = 0; c < 3; ++c) {
        out.sh[stride * g + 3 * k + c] = static_cast<float>(colour.basis[k] * d_rgb[c]);
      }
    }
  }
  return out;
}

}  // namespace

SurfelGradients SurfelGradients::Zeros(const GaussianCloud& cloud) {
  const size_t n = cloud.size();
  SurfelGradients out;
  out.positions.assign(3 * n, 0.0f);
  out.log_scales.assign(2 * n, 0.0f);
  out.rotations.assign(4 * n, 0.0f);
  out.opacity_logits.assign(n, 0.0f);
  out.sh.assign(cloud.sh.size(), 0.0f);
  return out;
}

absl::StatusOr<SurfelImage> RenderSurfelsDifferentiable(const GaussianCloud& cloud,
                                                        const PinholeCamera& camera,
                                                        const SurfelRenderOptions& options) {
  if (absl::Status s = Check(cloud, camera); !s.ok()) return s;
  const Prepared p = Prepare(cloud, camera, options);
  SurfelImage image;
  image.width = camera.width;
  image.height = camera.height;
  image.color.assign(static_cast<size_t>(3) * camera.width * camera.height, 0.0f);
  image.alpha.assign(static_cast<size_t>(camera.width) * camera.height, 0.0f);
  // Rows in parallel: every pixel is written by exactly one task.
  tbb::parallel_for(0, camera.height, [&](int y) {
    std::vector<Contributor> list;
    for (int x = 0; x < camera.width; ++x) {
      const double T = BlendPixel(p, x, y, &list);
      Eigen::Vector3d c = Eigen::Vector3d::Zero();
      for (const Contributor& k : list) c += k.alpha * k.T * p.colours[k.g].rgb;
      const size_t i = static_cast<size_t>(y) * camera.width + x;
      for (int ch = 0; ch < 3; ++ch) {
        image.color[3 * i + ch] = static_cast<float>(c[ch] + T * options.background[ch]);
      }
      image.alpha[i] = static_cast<float>(1.0 - T);
    }
  });
  return image;
}

absl::StatusOr<double> WeightedImageSum(const GaussianCloud& cloud, const PinholeCamera& camera,
                                        const SurfelRenderOptions& options,
                                        const std::vector<float>& weight_color,
                                        const std::vector<float>& weight_alpha) {
  if (absl::Status s = Check(cloud, camera); !s.ok()) return s;
  const Prepared p = Prepare(cloud, camera, options);
  std::vector<Contributor> list;
  double sum = 0;
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      const double T = BlendPixel(p, x, y, &list);
      const size_t i = static_cast<size_t>(y) * camera.width + x;
      Eigen::Vector3d c =
          T * Eigen::Vector3d(options.background[0], options.background[1], options.background[2]);
      for (const Contributor& k : list) c += k.alpha * k.T * p.colours[k.g].rgb;
      for (int ch = 0; ch < 3; ++ch) sum += weight_color[3 * i + ch] * c[ch];
      if (!weight_alpha.empty()) sum += weight_alpha[i] * (1.0 - T);
    }
  }
  return sum;
}

absl::StatusOr<SurfelGradients> SurfelBackward(const GaussianCloud& cloud,
                                               const PinholeCamera& camera,
                                               const SurfelRenderOptions& options,
                                               const std::vector<float>& dloss_dcolor,
                                               const std::vector<float>& dloss_dalpha) {
  if (absl::Status s = Check(cloud, camera); !s.ok()) return s;
  const size_t pixels = static_cast<size_t>(camera.width) * camera.height;
  if (dloss_dcolor.size() != 3 * pixels ||
      (!dloss_dalpha.empty() && dloss_dalpha.size() != pixels)) {
    return absl::InvalidArgumentError("surfel backward: loss gradients do not match the image");
  }
  const Prepared p = Prepare(cloud, camera, options);
  const size_t n = cloud.size();
  // One band of 16 rows per task, each with its own sparse accumulators; the bands are then summed
  // in band order, so the result does not depend on the thread count.
  const int bands = (camera.height + kTile - 1) / kTile;
  std::vector<BandGradients> band_grads(bands);
  tbb::parallel_for(0, bands, [&](int band) {
    band_grads[band] = BackwardBand(cloud, camera, options, p, dloss_dcolor, dloss_dalpha, band);
  });
  std::vector<Deriv> d_geometry(n, Deriv::Zero());                    // dL / d (p, log s, q, logit)
  std::vector<Eigen::Vector3d> d_colour(n, Eigen::Vector3d::Zero());  // dL / d rgb
  for (const BandGradients& band : band_grads) {
    for (size_t k = 0; k < band.touched.size(); ++k) {
      d_geometry[band.touched[k]] += band.geometry[k];
      d_colour[band.touched[k]] += band.colour[k];
    }
  }
  return ParameterGradients(cloud, p, d_geometry, d_colour);
}

}  // namespace instascene
