#include "common/raster/surfel_backward.h"

#include <tbb/parallel_for.h>
#include <unsupported/Eigen/AutoDiff>

#include <algorithm>
#include <cmath>
#include <numeric>

#include "absl/strings/str_cat.h"
#include "common/splat/sh.h"

namespace instascene {
namespace {

constexpr double kAlphaMinD = 1.0 / 255.0;
constexpr double kAlphaMaxD = 0.99;
constexpr double kTMin = 1e-4;
constexpr double kShC1 = 0.4886025119029199;

using Deriv = Eigen::Matrix<double, 10, 1>;  // position 3, log-scale 2, quaternion 4, logit 1
using Dual = Eigen::AutoDiffScalar<Deriv>;

struct Camera {
  double fx, fy, cx, cy;  // pixel centres at integers
  Eigen::Matrix3d rotation;
  Eigen::Vector3d translation, center;
  double near_plane;
};

Camera MakeCamera(const PinholeCamera& c, double near_plane) {
  return {c.fx,
          c.fy,
          c.cx - 0.5,
          c.cy - 0.5,
          c.camera_from_world.rotation,
          c.camera_from_world.translation,
          c.CenterInWorld(),
          near_plane};
}

// The surfel's parameters as scalars of type S (double, or Dual seeded with unit derivatives).
template <typename S>
struct SurfelParams {
  Eigen::Matrix<S, 3, 1> position;
  S log_scale[2];
  S quat[4];  // w x y z, not normalised
  S logit;
};

SurfelParams<double> Plain(const GaussianCloud& cloud, size_t g) {
  SurfelParams<double> s;
  for (int k = 0; k < 3; ++k) s.position[k] = cloud.positions[3 * g + k];
  for (int k = 0; k < 2; ++k) s.log_scale[k] = cloud.log_scales[2 * g + k];
  for (int k = 0; k < 4; ++k) s.quat[k] = cloud.rotations[4 * g + k];
  s.logit = cloud.opacity_logits[g];
  return s;
}

SurfelParams<Dual> Seeded(const GaussianCloud& cloud, size_t g) {
  const SurfelParams<double> p = Plain(cloud, g);
  SurfelParams<Dual> s;
  int k = 0;
  for (int i = 0; i < 3; ++i, ++k) s.position[i] = Dual(p.position[i], Deriv::Unit(k));
  for (int i = 0; i < 2; ++i, ++k) s.log_scale[i] = Dual(p.log_scale[i], Deriv::Unit(k));
  for (int i = 0; i < 4; ++i, ++k) s.quat[i] = Dual(p.quat[i], Deriv::Unit(k));
  s.logit = Dual(p.logit, Deriv::Unit(k));
  return s;
}

// The rows Tu, Tv, Tw of M = K V H (ALGORITHM.md 2.2) and the projected centre.
template <typename S>
struct Splat {
  Eigen::Matrix<S, 3, 1> tu, tv, tw;
  S center_x, center_y;  // low-pass filter centre (screen box centre)
  S proj_x, proj_y;      // projected surfel centre
  S depth, opacity;
};

template <typename S>
Splat<S> Project(const SurfelParams<S>& s, const Camera& cam) {
  using std::exp;
  using std::sqrt;
  const S norm = sqrt(s.quat[0] * s.quat[0] + s.quat[1] * s.quat[1] + s.quat[2] * s.quat[2] +
                      s.quat[3] * s.quat[3]);
  const S w = s.quat[0] / norm, x = s.quat[1] / norm, y = s.quat[2] / norm, z = s.quat[3] / norm;
  Eigen::Matrix<S, 3, 1> r0, r1;  // rotation columns 0 and 1
  r0 << S(1) - S(2) * (y * y + z * z), S(2) * (x * y + w * z), S(2) * (x * z - w * y);
  r1 << S(2) * (x * y - w * z), S(1) - S(2) * (x * x + z * z), S(2) * (y * z + w * x);
  const Eigen::Matrix<S, 3, 3> rc = cam.rotation.cast<S>();
  const Eigen::Matrix<S, 3, 1> a = rc * (r0 * exp(s.log_scale[0]));
  const Eigen::Matrix<S, 3, 1> b = rc * (r1 * exp(s.log_scale[1]));
  const Eigen::Matrix<S, 3, 1> c = rc * s.position + cam.translation.cast<S>();
  auto k = [&](const Eigen::Matrix<S, 3, 1>& v) {  // K v, homogeneous pixel coordinates
    Eigen::Matrix<S, 3, 1> out;
    out << S(cam.fx) * v[0] + S(cam.cx) * v[2], S(cam.fy) * v[1] + S(cam.cy) * v[2], v[2];
    return out;
  };
  const Eigen::Matrix<S, 3, 1> ka = k(a), kb = k(b), kc = k(c);
  Splat<S> sp;
  sp.tu << ka[0], kb[0], kc[0];
  sp.tv << ka[1], kb[1], kc[1];
  sp.tw << ka[2], kb[2], kc[2];
  sp.proj_x = kc[0] / kc[2];
  sp.proj_y = kc[1] / kc[2];
  // The low-pass filter's centre: the centre of the screen box of the 3-sigma ellipse, as the
  // production rasterizer (projection.cc, compute_aabb of the 2DGS CUDA code) has it.
  const S d = S(9) * sp.tw[0] * sp.tw[0] + S(9) * sp.tw[1] * sp.tw[1] - sp.tw[2] * sp.tw[2];
  const S f0 = S(9) / d, f2 = S(-1) / d;
  sp.center_x = f0 * sp.tu[0] * sp.tw[0] + f0 * sp.tu[1] * sp.tw[1] + f2 * sp.tu[2] * sp.tw[2];
  sp.center_y = f0 * sp.tv[0] * sp.tw[0] + f0 * sp.tv[1] * sp.tw[1] + f2 * sp.tv[2] * sp.tw[2];
  sp.depth = c[2];
  sp.opacity = S(1) / (S(1) + exp(-s.logit));
  return sp;
}

// Alpha of the splat at pixel (px, py) (pixel centres at integers), before the 0.99 clamp; 0 when
// the intersection is invalid (behind the near plane, parallel plane).
template <typename S>
S RawAlpha(const Splat<S>& sp, double px, double py, double near_plane) {
  using std::exp;
  const Eigen::Matrix<S, 3, 1> k = S(px) * sp.tw - sp.tu;
  const Eigen::Matrix<S, 3, 1> l = S(py) * sp.tw - sp.tv;
  const S pz = k[0] * l[1] - k[1] * l[0];
  if (pz == S(0)) return S(0);
  const S u = (k[1] * l[2] - k[2] * l[1]) / pz;
  const S v = (k[2] * l[0] - k[0] * l[2]) / pz;
  const S rho3d = u * u + v * v;
  const S dx = sp.center_x - S(px), dy = sp.center_y - S(py);
  const S rho2d = S(2) * (dx * dx + dy * dy);
  const bool use3d = rho3d <= rho2d;
  const S depth = use3d ? u * sp.tw[0] + v * sp.tw[1] + sp.tw[2] : sp.tw[2];
  if (depth < S(near_plane)) return S(0);
  return sp.opacity * exp(S(-0.5) * (use3d ? rho3d : rho2d));
}

// View-dependent colour (SH degree 0 or 1), clamped at 0 as the CUDA code does; also returns
// d colour / d position (3x3) and d colour / d sh coefficient via the basis.
struct Colour {
  Eigen::Vector3d rgb;
  Eigen::Matrix3d d_position;  // row = channel
  double basis[4];             // SH basis values (degree 0: basis[0] only)
  bool clamped[3];
};

Colour SurfelColour(const GaussianCloud& cloud, size_t g, const Camera& cam) {
  Colour out;
  const int stride = cloud.sh_stride();
  const float* sh = &cloud.sh[stride * g];
  const Eigen::Vector3d p(cloud.positions[3 * g], cloud.positions[3 * g + 1],
                          cloud.positions[3 * g + 2]);
  const Eigen::Vector3d diff = p - cam.center;
  const double len = diff.norm();
  const Eigen::Vector3d d = diff / len;
  out.basis[0] = kShC0;
  out.basis[1] = -kShC1 * d.y();
  out.basis[2] = kShC1 * d.z();
  out.basis[3] = -kShC1 * d.x();
  // d basis / d dir, then d dir / d p = (I - d d^T) / len.
  Eigen::Matrix<double, 4, 3> db_ddir = Eigen::Matrix<double, 4, 3>::Zero();
  db_ddir(1, 1) = -kShC1;
  db_ddir(2, 2) = kShC1;
  db_ddir(3, 0) = -kShC1;
  const Eigen::Matrix3d ddir_dp = (Eigen::Matrix3d::Identity() - d * d.transpose()) / len;
  const int coeffs = cloud.sh_degree == 0 ? 1 : 4;
  for (int c = 0; c < 3; ++c) {
    double value = 0.5;
    Eigen::RowVector3d grad = Eigen::RowVector3d::Zero();
    for (int k = 0; k < coeffs; ++k) {
      value += out.basis[k] * sh[3 * k + c];
      grad += sh[3 * k + c] * db_ddir.row(k) * ddir_dp;
    }
    out.clamped[c] = value < 0;
    out.rgb[c] = std::max(0.0, value);
    out.d_position.row(c) = out.clamped[c] ? Eigen::RowVector3d::Zero() : grad;
  }
  return out;
}

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
  struct Band {
    std::vector<uint32_t> touched;
    std::vector<Deriv> geometry;          // parallel to touched
    std::vector<Eigen::Vector3d> colour;  // parallel to touched
  };
  std::vector<Band> band_grads(bands);
  tbb::parallel_for(0, bands, [&](int band) {
    Band& out = band_grads[band];
    std::vector<int32_t> slot(n, -1);
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
  });
  std::vector<Deriv> d_geometry(n, Deriv::Zero());                    // dL / d (p, log s, q, logit)
  std::vector<Eigen::Vector3d> d_colour(n, Eigen::Vector3d::Zero());  // dL / d rgb
  for (const Band& band : band_grads) {
    for (size_t k = 0; k < band.touched.size(); ++k) {
      d_geometry[band.touched[k]] += band.geometry[k];
      d_colour[band.touched[k]] += band.colour[k];
    }
  }
  SurfelGradients out = SurfelGradients::Zeros(cloud);
  const int stride = cloud.sh_stride();
  const int coeffs = cloud.sh_degree == 0 ? 1 : 4;
  for (size_t g = 0; g < n; ++g) {
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

}  // namespace instascene
