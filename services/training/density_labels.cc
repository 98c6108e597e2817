#include "services/training/density_labels.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <tuple>

#include "absl/strings/str_cat.h"
#include "common/core/status.h"
#include "common/geometry/point_index.h"

namespace instascene::training {
namespace {

using VoxelKey = std::tuple<int, int, int>;

// Voxel of every Gaussian (index into the sorted voxel list) at side `voxel`.
std::vector<uint32_t> AssignVoxels(const std::vector<Eigen::Vector3f>& unit, double voxel,
                                   size_t* count) {
  std::map<VoxelKey, uint32_t> ids;
  std::vector<VoxelKey> keys(unit.size());
  for (size_t g = 0; g < unit.size(); ++g) {
    const Eigen::Vector3f& p = unit[g];
    keys[g] = {static_cast<int>(std::floor((p.x() + 1.0) / voxel)),
               static_cast<int>(std::floor((p.y() + 1.0) / voxel)),
               static_cast<int>(std::floor((p.z() + 1.0) / voxel))};
    ids.emplace(keys[g], 0);
  }
  uint32_t next = 0;
  for (auto& [key, id] : ids) id = next++;  // ordered by key: independent of Gaussian order
  std::vector<uint32_t> voxel_of(unit.size());
  for (size_t g = 0; g < unit.size(); ++g) voxel_of[g] = ids.at(keys[g]);
  *count = ids.size();
  return voxel_of;
}

// Centres in [-1, 1] by the robust box.
std::vector<Eigen::Vector3f> UnitCentres(const GaussianCloud& cloud) {
  const Eigen::AlignedBox3f box = RobustBounds(cloud);
  const Eigen::Vector3f centre = box.center();
  const float half = std::max(0.5f * box.sizes().maxCoeff(), 1e-6f);
  std::vector<Eigen::Vector3f> unit(cloud.size());
  for (size_t g = 0; g < cloud.size(); ++g) {
    const Eigen::Vector3f p(&cloud.positions[3 * g]);
    unit[g] = ((p - centre) / half).cwiseMax(-1.0f).cwiseMin(1.0f);
  }
  return unit;
}

// Per voxel: the mean normalised feature and the mean centre of its Gaussians.
void VoxelMeans(const std::vector<float>& features, int dim,
                const std::vector<Eigen::Vector3f>& unit, const std::vector<uint32_t>& voxel_of,
                size_t voxels, std::vector<float>* mean, std::vector<Eigen::Vector3f>* centres) {
  mean->assign(voxels * dim, 0.0f);
  centres->assign(voxels, Eigen::Vector3f::Zero());
  std::vector<uint32_t> members(voxels, 0);
  for (size_t g = 0; g < unit.size(); ++g) {
    const float* f = &features[g * dim];
    double norm = 0;
    for (int d = 0; d < dim; ++d) norm += double(f[d]) * f[d];
    const float inv = static_cast<float>(1.0 / (std::sqrt(norm) + 1e-9));
    float* m = &(*mean)[voxel_of[g] * dim];
    for (int d = 0; d < dim; ++d) m[d] += f[d] * inv;
    (*centres)[voxel_of[g]] += unit[g];
    ++members[voxel_of[g]];
  }
  for (size_t v = 0; v < voxels; ++v) {
    for (int d = 0; d < dim; ++d) (*mean)[v * dim + d] /= static_cast<float>(members[v]);
    (*centres)[v] /= static_cast<float>(members[v]);
  }
}

// Noise voxels (cluster < 0) take the cluster of the nearest clustered voxel; false when no
// voxel is clustered.
bool AssignNoise(const std::vector<Eigen::Vector3f>& centres, std::vector<int>* clusters) {
  std::vector<Eigen::Vector3f> clustered;
  std::vector<int> clustered_label;
  for (size_t v = 0; v < centres.size(); ++v) {
    if ((*clusters)[v] < 0) continue;
    clustered.push_back(centres[v]);
    clustered_label.push_back((*clusters)[v]);
  }
  if (clustered.empty()) return false;
  PointIndex3 index(std::move(clustered));
  for (size_t v = 0; v < centres.size(); ++v) {
    if ((*clusters)[v] >= 0) continue;
    (*clusters)[v] = clustered_label[index.Nearest(centres[v]).first];
  }
  return true;
}

}  // namespace

absl::StatusOr<DensityLabels> LabelByDensity(const GaussianCloud& cloud,
                                             const std::vector<float>& features, int dim,
                                             const DensityLabelOptions& options) {
  const size_t n = cloud.size();
  if (dim < 1 || features.size() != n * static_cast<size_t>(dim))
    return absl::InvalidArgumentError(absl::StrCat("density labels: ", features.size(),
                                                   " feature values for ", n, " Gaussians of ",
                                                   "dimension ", dim));
  if (!(options.voxel > 0) || options.max_points < 2)
    return absl::InvalidArgumentError("density labels: need voxel > 0 and max_points >= 2");
  DensityLabels out;
  out.labels.assign(n, 0);
  if (n < 2) return out;
  const std::vector<Eigen::Vector3f> unit = UnitCentres(cloud);
  double voxel = options.voxel;
  size_t voxels = 0;
  std::vector<uint32_t> voxel_of = AssignVoxels(unit, voxel, &voxels);
  while (voxels > static_cast<size_t>(options.max_points)) {
    voxel *= 2;
    voxel_of = AssignVoxels(unit, voxel, &voxels);
  }
  std::vector<float> mean;
  std::vector<Eigen::Vector3f> centres;
  VoxelMeans(features, dim, unit, voxel_of, voxels, &mean, &centres);
  out.clustered_points = voxels;
  out.voxel = voxel;
  if (voxels < 2) return out;
  ASSIGN_OR_RETURN(std::vector<int> clusters, Hdbscan(mean.data(), voxels, dim, options.hdbscan));
  if (!AssignNoise(centres, &clusters)) return out;  // nothing clustered: every Gaussian stays 0
  out.clusters = static_cast<size_t>(*std::max_element(clusters.begin(), clusters.end()) + 1);
  for (size_t g = 0; g < n; ++g) out.labels[g] = static_cast<uint32_t>(clusters[voxel_of[g]] + 1);
  return out;
}

size_t ReturnCoarseBackground(const std::vector<uint32_t>& coarse, double share,
                              std::vector<uint32_t>* labels) {
  if (share <= 0 || coarse.size() != labels->size()) return 0;
  // Per cluster: its size and how many of its Gaussians each coarse instance holds.
  std::map<uint32_t, size_t> size;
  std::map<uint32_t, std::map<uint32_t, size_t>> held;
  for (size_t g = 0; g < labels->size(); ++g) {
    const uint32_t c = (*labels)[g];
    if (c == 0) continue;
    ++size[c];
    if (coarse[g] > 0) ++held[c][coarse[g]];
  }
  std::set<uint32_t> found;  // clusters mostly one coarse instance
  for (const auto& [c, counts] : held) {
    size_t most = 0;
    for (const auto& [instance, n] : counts) most = std::max(most, n);
    if (static_cast<double>(most) >= share * static_cast<double>(size[c])) found.insert(c);
  }
  size_t returned = 0;
  for (size_t g = 0; g < labels->size(); ++g) {
    if (coarse[g] == 0 && found.count((*labels)[g])) {
      (*labels)[g] = 0;
      ++returned;
    }
  }
  return returned;
}

}  // namespace instascene::training
