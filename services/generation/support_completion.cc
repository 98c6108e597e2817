#include "services/generation/support_completion.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "common/geometry/point_index.h"

namespace instascene::generation {

namespace {

// About a vertical axis of revolution the surface's normal line meets the axis; the sphere about
// that point through the surfel is the sphere itself on a ball and curves inwards of the tangent
// elsewhere (the tangent ran 4 mm outside a ball's underside). Appends the candidates down that
// sphere to `out` (to the support's floor) and returns true, or returns false where the normal
// line does not meet the axis above the surfel (the caller goes down the tangent instead).
bool CurvedWallCandidates(const Eigen::Vector3f& position, const Eigen::Matrix3f& rotation,
                          uint32_t source, const Eigen::Vector3f& axis_point,
                          const ObjectFrame& frame, float floor,
                          std::vector<SurfelCandidate>& out) {
  const float step = std::max(frame.spacing, 1e-6f);
  const Eigen::Vector3f normal = rotation.col(2);
  const float lean = normal.dot(frame.up);
  const float h = frame.up.dot(position);
  const Eigen::Vector3f from_axis = position - axis_point;
  const Eigen::Vector3f radial_offset = from_axis - from_axis.dot(frame.up) * frame.up;
  const float r0 = radial_offset.norm();
  if (r0 <= step) return false;
  const Eigen::Vector3f e_r = radial_offset / r0;
  const float n_r = normal.dot(e_r);
  if (std::abs(n_r) <= 1e-3f) return false;
  // Heights relative to the surfel: the normal line reaches the axis at rise = -r0 n_h / n_r
  // (above the surfel where the surface narrows downwards).
  const float rise = -r0 * lean / n_r;
  if (rise <= 0) return false;
  const float rho = std::hypot(r0, rise);
  const float alpha0 = std::atan2(r0, rise);  // from straight down about the centre
  const Eigen::Vector3f n0 = std::sin(alpha0) * e_r - std::cos(alpha0) * frame.up;
  for (float alpha = alpha0 - step / rho; alpha > 0; alpha -= step / rho) {
    const float r = rho * std::sin(alpha), dh = rise - rho * std::cos(alpha);
    if (h + dh < floor) break;
    const Eigen::Vector3f n1 = std::sin(alpha) * e_r - std::cos(alpha) * frame.up;
    SurfelCandidate c;
    c.position = position + (r - r0) * e_r + dh * frame.up;
    c.rotation = Eigen::Quaternionf::FromTwoVectors(n0, n1).toRotationMatrix() * rotation;
    c.source = source;
    out.push_back(c);
  }
  return true;
}

// Azimuth sectors (5 degrees) around the object's centre, in its frame.
class AzimuthSectors {
 public:
  static constexpr int kCount = 72;
  explicit AzimuthSectors(const ObjectFrame& frame)
      : basis_(frame.Basis()), center_(frame.center) {}
  int Of(const Eigen::Vector3f& p) const {
    const Eigen::Vector3f q = basis_.transpose() * (p - center_);
    const float angle = std::atan2(q.y(), q.x());  // [-pi, pi]
    return std::clamp(static_cast<int>((angle + 3.14159265f) / (2 * 3.14159265f) * kCount), 0,
                      kCount - 1);
  }

 private:
  Eigen::Matrix3f basis_;
  Eigen::Vector3f center_;
};

// Copies of a surfel every `step` along `down` (per unit of height) while above `floor`.
void AppendDrop(const Eigen::Vector3f& position, const Eigen::Matrix3f& rotation, uint32_t source,
                const Eigen::Vector3f& down, float height, float floor, float step,
                std::vector<SurfelCandidate>& out) {
  for (float drop = step; height - drop >= floor; drop += step) {
    SurfelCandidate c;
    c.position = position + drop * down;
    c.rotation = rotation;
    c.source = source;
    out.push_back(c);
  }
}

}  // namespace

std::vector<SurfelCandidate> WallExtension(const std::vector<Eigen::Vector3f>& positions,
                                           const std::vector<Eigen::Matrix3f>& rotations,
                                           const std::vector<uint32_t>& sources,
                                           const ObjectFrame& frame, float slope_min_sin,
                                           const std::optional<Eigen::Vector3f>& vertical_axis) {
  std::vector<SurfelCandidate> out;
  if (!frame.has_support || positions.empty()) return out;
  // The lowest surfel per azimuth sector around the centre: how far down each side was seen.
  const AzimuthSectors sectors(frame);
  std::vector<float> lowest(AzimuthSectors::kCount, std::numeric_limits<float>::infinity());
  for (const Eigen::Vector3f& p : positions) {
    float& l = lowest[sectors.Of(p)];
    l = std::min(l, frame.up.dot(p));
  }
  const float step = std::max(frame.spacing, 1e-6f);
  const float floor = frame.support_height + 0.5f * step;
  const float band = std::max(3.0f * step, 0.05f * frame.radius);
  for (size_t i = 0; i < positions.size(); ++i) {
    const float h = frame.up.dot(positions[i]);
    const float sector_lowest = lowest[sectors.Of(positions[i])];
    if (h > sector_lowest + band || sector_lowest - floor < step) continue;
    const Eigen::Vector3f normal = rotations[i].col(2);
    const float lean = normal.dot(frame.up);
    if (std::abs(lean) > 0.7f) continue;  // not wall-like
    // Per unit of height dropped: straight down, or, where the surface narrows towards the
    // support (a sphere's or a bowl's underside), down the surfel's slope (the steepest descent
    // in its tangent plane, at most 45 degrees off vertical here, so inwards by at most the
    // drop). A surface widening downwards (a shoulder) goes straight down: outwards, a tall drop
    // from a bottle's shoulder ran 4 cm past its body. Inwards or outwards is the descent's
    // against the surfel's offset from the axis, whichever way its normal points.
    Eigen::Vector3f down = -frame.up;
    const Eigen::Vector3f descent = -(frame.up - lean * normal);
    const Eigen::Vector3f offset = positions[i] - vertical_axis.value_or(frame.center);
    const bool narrowing = slope_min_sin > 0 && std::abs(lean) > slope_min_sin &&
                           descent.dot(offset - offset.dot(frame.up) * frame.up) < 0;
    if (narrowing && vertical_axis.has_value() &&
        CurvedWallCandidates(positions[i], rotations[i], sources[i], *vertical_axis, frame, floor,
                             out)) {
      continue;
    }
    if (narrowing) down = descent / -descent.dot(frame.up);
    AppendDrop(positions[i], rotations[i], sources[i], down, h, floor, step, out);
  }
  return out;
}

namespace {

// A square grid of cells on the support plane around the object (frame basis x, y).
struct CapGrid {
  float cell = 0;
  int half = 0, side = 0;
  bool Cell(const Eigen::Vector3f& q, int* i, int* j) const {
    *i = static_cast<int>(std::floor(q.x() / cell)) + half;
    *j = static_cast<int>(std::floor(q.y() / cell)) + half;
    return *i >= 0 && *j >= 0 && *i < side && *j < side;
  }
};

// The cells the lower quarter of the object covers seen from above (its walls, once extended
// down to the support), and those surfels with their sources.
std::vector<uint8_t> LowCells(const std::vector<Eigen::Vector3f>& positions,
                              const std::vector<uint32_t>& sources, const ObjectFrame& frame,
                              const CapGrid& grid, std::vector<Eigen::Vector3f>* low,
                              std::vector<uint32_t>* low_sources) {
  const Eigen::Matrix3f basis = frame.Basis();
  std::vector<uint8_t> occupied(static_cast<size_t>(grid.side) * grid.side, 0);
  float top = -std::numeric_limits<float>::infinity();
  for (const Eigen::Vector3f& p : positions) top = std::max(top, frame.up.dot(p));
  const float contact = frame.support_height + 0.25f * (top - frame.support_height);
  for (size_t k = 0; k < positions.size(); ++k) {
    if (frame.up.dot(positions[k]) > contact) continue;
    low->push_back(positions[k]);
    low_sources->push_back(sources[k]);
    int i = 0, j = 0;
    if (grid.Cell(basis.transpose() * (positions[k] - frame.center), &i, &j))
      occupied[j * grid.side + i] = 1;
  }
  return occupied;
}

// The cells outside the convex hull of the occupied ones: a completed wall may keep gaps
// (candidates refused near silhouettes), through which filling the outline's holes leaked and
// left boxes without a bottom. Concave footprints lose nothing real: where the hull spans space
// a view saw empty (a torus' hole, an L's inner corner), the free-space check drops the cell.
std::vector<uint8_t> OutsideHull(const std::vector<uint8_t>& occupied, int side) {
  std::vector<cv::Point> cells;
  for (int j = 0; j < side; ++j) {
    for (int i = 0; i < side; ++i) {
      if (occupied[j * side + i]) cells.emplace_back(i, j);
    }
  }
  std::vector<cv::Point> hull;
  cv::convexHull(cells, hull);
  cv::Mat footprint(side, side, CV_8U, cv::Scalar(0));
  cv::fillConvexPoly(footprint, hull, cv::Scalar(1), cv::LINE_8);
  std::vector<uint8_t> outside(occupied.size(), 0);
  for (int j = 0; j < side; ++j) {
    for (int i = 0; i < side; ++i) outside[j * side + i] = !footprint.at<uint8_t>(j, i);
  }
  return outside;
}

// Whether a cell touches the outside (or the grid's edge) among its 8 neighbours.
bool NextToOutside(const std::vector<uint8_t>& outside, int side, int i, int j) {
  for (int dj = -1; dj <= 1; ++dj) {
    for (int di = -1; di <= 1; ++di) {
      const int ni = i + di, nj = j + dj;
      if (ni < 0 || nj < 0 || ni >= side || nj >= side || outside[nj * side + ni]) return true;
    }
  }
  return false;
}

// The mean plane coordinates (x, y) of the low surfels in each cell, with their count in z.
std::vector<Eigen::Vector3f> CellMeans(const std::vector<Eigen::Vector3f>& low,
                                       const ObjectFrame& frame, const CapGrid& grid) {
  const Eigen::Matrix3f basis = frame.Basis();
  std::vector<Eigen::Vector3f> sum(static_cast<size_t>(grid.side) * grid.side,
                                   Eigen::Vector3f::Zero());
  for (const Eigen::Vector3f& p : low) {
    const Eigen::Vector3f q = basis.transpose() * (p - frame.center);
    int i = 0, j = 0;
    if (grid.Cell(q, &i, &j)) sum[j * grid.side + i] += Eigen::Vector3f(q.x(), q.y(), 1);
  }
  for (Eigen::Vector3f& m : sum) {
    if (m.z() > 0) m.head<2>() /= m.z();
  }
  return sum;
}

// A rim cell's cap point no farther out than its wall: the cell's centre, moved back along the
// outward direction (away from the footprint's cells around it) onto the line through the
// mean of the wall's surfels in the cell where the centre stands beyond it.
Eigen::Vector2f InsideTheWall(const Eigen::Vector2f& centre, const Eigen::Vector3f& wall,
                              const std::vector<uint8_t>& outside, const CapGrid& grid, int i,
                              int j) {
  if (wall.z() <= 0) return centre;
  Eigen::Vector2f inward = Eigen::Vector2f::Zero();
  for (int dj = -1; dj <= 1; ++dj) {
    for (int di = -1; di <= 1; ++di) {
      const int ni = i + di, nj = j + dj;
      const bool in =
          ni >= 0 && nj >= 0 && ni < grid.side && nj < grid.side && !outside[nj * grid.side + ni];
      if (in) inward += Eigen::Vector2f(static_cast<float>(di), static_cast<float>(dj));
    }
  }
  if (inward.norm() < 1e-6f) return centre;
  const Eigen::Vector2f out = -inward.normalized();
  const float beyond = (centre - wall.head<2>()).dot(out);
  return beyond > 0 ? Eigen::Vector2f(centre - beyond * out) : centre;
}

}  // namespace

std::vector<SurfelCandidate> SupportCap(const std::vector<Eigen::Vector3f>& positions,
                                        const std::vector<uint32_t>& sources,
                                        const ObjectFrame& frame, const FreeSpaceGrid& free_space,
                                        bool rim_inside_walls) {
  std::vector<SurfelCandidate> out;
  if (!frame.has_support || positions.empty()) return out;
  const Eigen::Matrix3f basis = frame.Basis();
  CapGrid grid;
  grid.cell = std::max(1.5f * frame.spacing, frame.radius / 64.0f);
  grid.half = static_cast<int>(std::ceil(1.5f * frame.radius / grid.cell));
  grid.side = 2 * grid.half + 1;
  std::vector<Eigen::Vector3f> low;
  std::vector<uint32_t> low_sources;
  const std::vector<uint8_t> seen = LowCells(positions, sources, frame, grid, &low, &low_sources);
  if (low.empty()) return out;
  const std::vector<uint8_t> outside = OutsideHull(seen, grid.side);
  const PointIndex3 low_index(low);
  const Eigen::Vector3f plane_origin =
      frame.center +
      (frame.support_height + 0.25f * frame.spacing - frame.up.dot(frame.center)) * frame.up;
  const float lift = 3.0f * free_space.voxel();
  const int side = grid.side, half = grid.half;
  const std::vector<Eigen::Vector3f> wall = CellMeans(low, frame, grid);
  for (int j = 0; j < side; ++j) {
    for (int i = 0; i < side; ++i) {
      if (outside[j * side + i]) continue;
      // A cell on the hull's rim is footprint only where a surfel lies in it, else the cap would
      // overhang the walls by a cell.
      const bool rim = NextToOutside(outside, side, i, j);
      if (!seen[j * side + i] && rim) continue;
      Eigen::Vector2f at((i - half + 0.5f) * grid.cell, (j - half + 0.5f) * grid.cell);
      if (rim && rim_inside_walls) at = InsideTheWall(at, wall[j * side + i], outside, grid, i, j);
      SurfelCandidate c;
      c.position = plane_origin + basis.col(0) * at.x() + basis.col(1) * at.y();
      if (free_space.IsFree(c.position + lift * frame.up)) continue;  // seen through: a hole
      c.rotation = basis;
      c.source = low_sources[low_index.Nearest(c.position).first];
      c.has_scale = true;
      c.log_scale_u = c.log_scale_v = std::log(0.6f * grid.cell);
      out.push_back(c);
    }
  }
  return out;
}

}  // namespace instascene::generation
