#include "services/generation/axis_bodies.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace instascene::generation {
namespace {

// An axis that most of the object contradicts (a tilted or offset fit) tells no handle from its
// own error.
constexpr double kMaxAxisAsymmetricShare = 0.3;

// Every surfel's height along the axis and distance from it.
struct AxisCoordinates {
  std::vector<float> height, radial;
};

AxisCoordinates CoordinatesAbout(const SymmetryHypothesis& axis, const InstanceSurfels& s) {
  AxisCoordinates c;
  c.height.resize(s.size());
  c.radial.resize(s.size());
  for (uint32_t g = 0; g < s.size(); ++g) {
    const Eigen::Vector3f d = s.points[g] - axis.point;
    c.height[g] = d.dot(axis.direction);
    c.radial[g] = (d - c.height[g] * axis.direction).norm();
  }
  return c;
}

// A handle's parts about a solid of revolution: components grown (within 3 spacings, repeatedly)
// from the sources beyond the body that the axis does not hold for, through surfels more than 2
// spacings beyond the body's median radius at their height (the 95th percentile of the body's
// radii, and the profile's 90th, stand on the handle's lower end where it is a tenth of the
// surfels). A part that reaches a surfel a neighbour's label surrounds is that neighbour's patch
// at the contact, not a handle: the profile rules judge it. The parts join `b->off`; those of
// fewer than `min_surfels` are no handle but a neighbour's stray (`out->small_part`).
void JoinHandleParts(const AxisCoordinates& c, float step, const InstanceSurfels& s,
                     int min_surfels, AxisBody* b, AxisBodies* out) {
  const size_t n = s.size();
  std::vector<uint8_t> held(n);
  for (uint32_t g = 0; g < n; ++g) held[g] = !b->off[g];
  const std::vector<float> median = RadialProfile(c.height, c.radial, held, step, 50);
  const float link = 3.0f * step;
  std::vector<uint8_t> seen(n, 0);
  std::vector<uint32_t> part, queue;
  for (uint32_t seed = 0; seed < n; ++seed) {
    if (!b->off_beyond_body[seed] || seen[seed] || s.NeighbourLabelled(seed)) continue;
    part.assign(1, seed);
    queue.assign(1, seed);
    seen[seed] = 1;
    bool touches = false;
    while (!queue.empty()) {
      const uint32_t g = queue.back();
      queue.pop_back();
      for (uint32_t m : s.index.WithinRadius(s.points[g], link)) {
        touches |= s.NeighbourLabelled(m);
        if (seen[m] || s.NeighbourLabelled(m) || c.radial[m] <= median[m] + 2.0f * step) continue;
        seen[m] = 1;  // each surfel enters one part once
        part.push_back(m);
        queue.push_back(m);
      }
    }
    if (touches) continue;
    const bool handle = part.size() >= static_cast<size_t>(std::max(min_surfels, 0));
    for (uint32_t g : part) {
      out->handle_joined += handle && !b->off[g];
      b->off[g] = 1;  // no witness of the profile either way
      b->off_beyond_body[g] = 1;
      (handle ? out->handle : out->small_part)[g] = 1;
    }
  }
}

// The profile rules about a solid of revolution (an n-fold axis's radius varies around it: a
// box's corners). The profile is the body's: a surfel a touching neighbour's label surrounds is a
// suspect it is to judge, not a witness (a neighbour's surfels crowding one height can be a tenth
// of the window and lift the percentile over themselves).
void ApplyProfile(const AxisCoordinates& c, float step, const InstanceSurfels& s,
                  const GeometricPriorOptions& options, AxisBody* b) {
  const size_t n = s.size();
  std::vector<uint8_t> holds(n);
  for (uint32_t g = 0; g < n; ++g)
    holds[g] = !b->off[g] && !(options.profile_skips_neighbour_labelled && s.NeighbourLabelled(g));
  std::vector<float> profile = RadialProfile(c.height, c.radial, holds, step);
  for (uint32_t g = 0; g < n; ++g)
    if (s.NeighbourLabelled(g)) profile[g] -= (1.0f - options.neighbour_profile_spacings) * step;
  for (uint32_t g = 0; g < n; ++g) b->beyond_profile[g] = !b->off[g] && c.radial[g] > profile[g];
  if (options.drop_neighbours_beyond_axis_profile && s.neighbour_labelled != nullptr) {
    b->neighbours_beyond_profile.assign(n, 0);
    b->off_beyond_profile.assign(n, 0);
    for (uint32_t g = 0; g < n; ++g) {
      b->off_beyond_profile[g] = b->off[g] && c.radial[g] > profile[g];
      b->neighbours_beyond_profile[g] = b->off_beyond_profile[g] && s.NeighbourLabelled(g);
    }
  }
}

}  // namespace

std::vector<uint8_t> AsymmetricSources(const SymmetryHypothesis& h, const InstanceSurfels& s,
                                       bool exact) {
  std::vector<uint8_t> asymmetric(s.size(), 0);
  for (uint32_t g = 0; g < s.size(); ++g) {
    int contradicted = 0;
    for (int k = 0; k < h.copies; ++k) {
      const Eigen::Vector3f image = h.MapPoint(s.points[g], k);
      contradicted += s.free_space.IsFree(image) && (!exact || s.seen_through == nullptr ||
                                                     s.seen_through->ViewsSeeingThrough(image) > 0);
    }
    asymmetric[g] = contradicted > std::max(0, h.copies / 4);
  }
  return asymmetric;
}

AxisBodies AnalyseAxisBodies(const std::vector<SymmetryHypothesis>& hypotheses,
                             const InstanceSurfels& s, const GeometricPriorOptions& options) {
  const size_t n = s.size();
  AxisBodies out;
  out.handle.assign(n, 0);
  out.small_part.assign(n, 0);
  const float step = std::max(s.frame.spacing, 1e-6f);
  for (const SymmetryHypothesis& axis : hypotheses) {
    if (!axis.accepted || axis.kind != SymmetryKind::kAxis) continue;
    AxisBody b;
    b.axis = &axis;
    b.off_beyond_body.assign(n, 0);
    b.beyond_profile.assign(n, 0);
    b.off = AsymmetricSources(axis, s, options.exact_asymmetry);
    const AxisCoordinates c = CoordinatesAbout(axis, s);
    std::vector<float> body;
    for (uint32_t g = 0; g < n; ++g)
      if (!b.off[g]) body.push_back(c.radial[g]);
    if (body.empty() || body.size() < (1.0 - kMaxAxisAsymmetricShare) * n) continue;
    // Only what sticks out beyond the body the axis holds for (a handle, not the body's own
    // surfels that a slightly offset axis revolves into seen-empty space).
    const size_t q = body.size() * 95 / 100;
    std::nth_element(body.begin(), body.begin() + q, body.end());
    const float reach = body[std::min(q, body.size() - 1)] + step;
    for (uint32_t g = 0; g < n; ++g) b.off_beyond_body[g] = b.off[g] && c.radial[g] > reach;
    // About a solid of revolution only (an n-fold axis's radius varies around it: a box's
    // corners stand clear of its median radius).
    if (options.handle_joins_its_part && axis.order == 0 &&
        std::find(b.off_beyond_body.begin(), b.off_beyond_body.end(), 1) !=
            b.off_beyond_body.end()) {
      const int min_surfels =
          std::max(options.min_handle_surfels,
                   static_cast<int>(std::ceil(options.min_handle_share * static_cast<float>(n))));
      JoinHandleParts(c, step, s, min_surfels, &b, &out);
    }
    if (options.skip_beyond_axis_profile && axis.order == 0) ApplyProfile(c, step, s, options, &b);
    // About an n-fold axis (no profile: a box's radius varies around it), those beyond the body's
    // reach (its corners) that the axis does not hold for and a neighbour's label surrounds.
    if (axis.order != 0 && options.drop_neighbours_beyond_axis_profile &&
        s.neighbour_labelled != nullptr) {
      b.neighbours_beyond_profile.assign(n, 0);
      for (uint32_t g = 0; g < n; ++g)
        b.neighbours_beyond_profile[g] = b.off_beyond_body[g] && s.NeighbourLabelled(g);
    }
    out.bodies.push_back(std::move(b));
  }
  return out;
}

std::vector<uint8_t> ForeignSurfels(const AxisBodies& bodies, const InstanceSurfels& s,
                                    const GeometricPriorOptions& options) {
  const size_t n = s.size();
  std::vector<uint8_t> foreign(n, 0);
  for (uint32_t g = 0; g < n; ++g) {
    foreign[g] = bodies.small_part[g];
    for (const AxisBody& b : bodies.bodies) {
      foreign[g] |= options.drop_beyond_axis_profile && b.beyond_profile[g];
      foreign[g] |= !b.neighbours_beyond_profile.empty() && b.neighbours_beyond_profile[g];
    }
  }
  if (!options.drop_patches_beyond_axis_profile) return foreign;
  // A neighbour's patch at the contact: surfels beyond the profile that the axis does not hold
  // for and that join a surfel found not to be the object's (within three spacings, repeatedly)
  // are not the object's either. They are the patch's inner part, too far from every other
  // instance's surfel for the neighbour-label test (its rim passes it).
  std::vector<uint8_t> candidate(n, 0);
  bool any = false;
  for (const AxisBody& b : bodies.bodies) {
    if (b.off_beyond_profile.empty()) continue;
    for (uint32_t g = 0; g < n; ++g) {
      candidate[g] |= b.off_beyond_profile[g] && !foreign[g] && !bodies.handle[g];
      any |= candidate[g] != 0;
    }
  }
  if (!any) return foreign;
  std::vector<uint32_t> queue;
  for (uint32_t g = 0; g < n; ++g)
    if (foreign[g]) queue.push_back(g);
  const float link = 3.0f * std::max(s.frame.spacing, 1e-6f);
  while (!queue.empty()) {
    const uint32_t g = queue.back();
    queue.pop_back();
    for (uint32_t m : s.index.WithinRadius(s.points[g], link)) {
      if (!candidate[m] || foreign[m]) continue;
      foreign[m] = 1;
      queue.push_back(m);
    }
  }
  return foreign;
}

std::vector<uint8_t> SkippedSources(const SymmetryHypothesis& h, const AxisBodies& bodies,
                                    const InstanceSurfels& s,
                                    const GeometricPriorOptions& options) {
  std::vector<uint8_t> skip = bodies.small_part;  // a neighbour's stray lends nothing
  skip.resize(s.size(), 0);
  const float sin_tolerance = std::sin(10.0f * static_cast<float>(M_PI) / 180.0f);
  for (const AxisBody& b : bodies.bodies) {
    const SymmetryHypothesis& axis = *b.axis;
    if (&h == &axis) {
      for (uint32_t g = 0; g < skip.size(); ++g) skip[g] |= b.beyond_profile[g];
      continue;
    }
    if (h.kind != SymmetryKind::kPlane || !options.mirror_skips_axis_asymmetric) continue;
    if (std::abs(axis.direction.dot(h.direction)) > sin_tolerance ||
        std::abs(h.direction.dot(axis.point - h.point)) > 2.0f * s.frame.spacing) {
      continue;  // the plane does not contain this axis
    }
    for (uint32_t g = 0; g < skip.size(); ++g)
      skip[g] |= b.off_beyond_body[g] | b.beyond_profile[g];
  }
  return skip;
}

std::vector<float> RadialProfile(const std::vector<float>& height, const std::vector<float>& radial,
                                 const std::vector<uint8_t>& body, float step, int percent,
                                 size_t min_count) {
  std::vector<float> out(height.size(), std::numeric_limits<float>::infinity());
  if (static_cast<size_t>(std::count(body.begin(), body.end(), 1)) < min_count) return out;
  const float low = *std::min_element(height.begin(), height.end());
  const int bins =
      static_cast<int>((*std::max_element(height.begin(), height.end()) - low) / step) + 1;
  auto bin_of = [&](size_t g) {
    return std::clamp(static_cast<int>((height[g] - low) / step), 0, bins - 1);
  };
  std::vector<std::vector<float>> by_bin(bins);
  for (size_t g = 0; g < height.size(); ++g) {
    if (body[g]) by_bin[bin_of(g)].push_back(radial[g]);
  }
  std::vector<size_t> below(bins + 1, 0);  // body surfels in bins [0, i)
  for (int i = 0; i < bins; ++i) below[i + 1] = below[i] + by_bin[i].size();
  std::vector<float> profile(bins), window;
  for (int i = 0; i < bins; ++i) {
    int half = 2;
    while (below[std::min(bins, i + half + 1)] - below[std::max(0, i - half)] < min_count) ++half;
    window.clear();
    for (int j = std::max(0, i - half); j <= std::min(bins - 1, i + half); ++j)
      window.insert(window.end(), by_bin[j].begin(), by_bin[j].end());
    const size_t q = window.size() * percent / 100;
    std::nth_element(window.begin(), window.begin() + q, window.end());
    profile[i] = window[q] + step;
  }
  for (size_t g = 0; g < height.size(); ++g) out[g] = profile[bin_of(g)];
  return out;
}

}  // namespace instascene::generation
