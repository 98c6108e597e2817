#include "common/synth/primitives.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace instascene {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;

std::vector<Eigen::Vector2f> Arc(Eigen::Vector2f center, float radius, float from_rad, float to_rad,
                                 int steps) {
  std::vector<Eigen::Vector2f> points;
  for (int i = 0; i <= steps; ++i) {
    const float a = from_rad + (to_rad - from_rad) * static_cast<float>(i) / steps;
    points.emplace_back(center.x() + radius * std::cos(a), center.y() + radius * std::sin(a));
  }
  return points;
}

void AppendQuad(TriangleMesh& mesh, uint32_t a, uint32_t b, uint32_t c, uint32_t d) {
  mesh.triangles.push_back({a, b, c});
  mesh.triangles.push_back({a, c, d});
}

TriangleMesh MakeBox(const Eigen::Vector3f& size) {
  TriangleMesh mesh;
  const Eigen::Vector3f h = 0.5f * size;
  // Each face: origin corner and two edge vectors (counter-clockwise seen from outside).
  const Eigen::Vector3f faces[6][3] = {
      {{-h.x(), -h.y(), 0}, {0, 2 * h.y(), 0}, {2 * h.x(), 0, 0}},         // bottom (-z)
      {{-h.x(), -h.y(), size.z()}, {2 * h.x(), 0, 0}, {0, 2 * h.y(), 0}},  // top (+z)
      {{-h.x(), -h.y(), 0}, {2 * h.x(), 0, 0}, {0, 0, size.z()}},          // -y
      {{h.x(), h.y(), 0}, {-2 * h.x(), 0, 0}, {0, 0, size.z()}},           // +y
      {{-h.x(), h.y(), 0}, {0, -2 * h.y(), 0}, {0, 0, size.z()}},          // -x
      {{h.x(), -h.y(), 0}, {0, 2 * h.y(), 0}, {0, 0, size.z()}},           // +x
  };
  constexpr int kCells = 4;
  for (int f = 0; f < 6; ++f) {
    const uint32_t base = static_cast<uint32_t>(mesh.vertices.size());
    for (int j = 0; j <= kCells; ++j) {
      for (int i = 0; i <= kCells; ++i) {
        const float u = static_cast<float>(i) / kCells, v = static_cast<float>(j) / kCells;
        mesh.vertices.push_back(faces[f][0] + u * faces[f][1] + v * faces[f][2]);
        mesh.uvs.emplace_back((f + u) / 6.0f, v);
      }
    }
    for (int j = 0; j < kCells; ++j) {
      for (int i = 0; i < kCells; ++i) {
        const uint32_t a = base + j * (kCells + 1) + i;
        AppendQuad(mesh, a, a + 1, a + kCells + 2, a + kCells + 1);
      }
    }
  }
  return mesh;
}

}  // namespace

std::string ShapeKindName(ShapeKind kind) {
  switch (kind) {
    case ShapeKind::kBox:
      return "box";
    case ShapeKind::kSphere:
      return "sphere";
    case ShapeKind::kCylinder:
      return "cylinder";
    case ShapeKind::kCone:
      return "cone";
    case ShapeKind::kTorus:
      return "torus";
    case ShapeKind::kBottle:
      return "bottle";
    case ShapeKind::kCup:
      return "cup";
    case ShapeKind::kBowl:
      return "bowl";
    case ShapeKind::kMug:
      return "mug";
    case ShapeKind::kLBlock:
      return "l-block";
    case ShapeKind::kIrregular:
      return "irregular";
  }
  return "?";
}

float ShapeSpec::FootprintRadius() const {
  switch (kind) {
    case ShapeKind::kBox:
      return 0.5f * std::hypot(size.x(), size.y());
    case ShapeKind::kLBlock:
    case ShapeKind::kIrregular:  // sheared and twisted: up to 1.3x the box
      return 0.5f * std::hypot(1.3f * size.x(), 1.3f * size.y());
    case ShapeKind::kTorus:
      return size.x() + size.y();
    case ShapeKind::kMug:  // the handle reaches 0.56 h beyond the wall
      return size.x() + 0.56f * size.z();
    default:
      return size.x();
  }
}

float ShapeSpec::Height() const {
  switch (kind) {
    case ShapeKind::kBox:
    case ShapeKind::kLBlock:
      return size.z();
    case ShapeKind::kIrregular:
      return 1.35f * size.z();
    case ShapeKind::kSphere:
      return 2.0f * size.x();
    case ShapeKind::kTorus:
      return 2.0f * size.y();
    default:
      return size.z();
  }
}

TriangleMesh MakeLathe(const std::vector<Eigen::Vector2f>& profile, int segments,
                       bool closed_loop) {
  TriangleMesh mesh;
  const int k = static_cast<int>(profile.size());
  std::vector<float> arc(k, 0.0f);
  for (int i = 1; i < k; ++i) arc[i] = arc[i - 1] + (profile[i] - profile[i - 1]).norm();
  const float total = std::max(arc.back(), 1e-9f);
  for (int i = 0; i < k; ++i) {
    for (int j = 0; j <= segments; ++j) {
      const float a = 2.0f * kPi * static_cast<float>(j) / segments;
      mesh.vertices.emplace_back(profile[i].x() * std::cos(a), profile[i].x() * std::sin(a),
                                 profile[i].y());
      mesh.uvs.emplace_back(static_cast<float>(j) / segments, arc[i] / total);
    }
  }
  const int rows = closed_loop ? k : k - 1;
  for (int i = 0; i < rows; ++i) {
    const int next = (i + 1) % k;
    for (int j = 0; j < segments; ++j) {
      const uint32_t a = i * (segments + 1) + j, b = next * (segments + 1) + j;
      // Quads with a zero radius edge degenerate to triangles; drop the zero-area one.
      if (profile[i].x() > 0.0f || profile[next].x() > 0.0f) {
        if (profile[i].x() == 0.0f) {
          mesh.triangles.push_back({a, b + 1, b});
        } else if (profile[next].x() == 0.0f) {
          mesh.triangles.push_back({a, a + 1, b});
        } else {
          AppendQuad(mesh, a, a + 1, b + 1, b);
        }
      }
    }
  }
  return mesh;
}

std::vector<ShapeTip> ShapeTips(const ShapeSpec& spec) {
  // The lathe's last profile point: arc-length fraction 1, angle 0.
  if (spec.kind == ShapeKind::kCone) return {{Eigen::Vector3f(0, 0, spec.size.z()), {0, 1}}};
  return {};
}

TriangleMesh MakeCenteredSphere(float radius, int segments) {
  ShapeSpec spec;
  spec.kind = ShapeKind::kSphere;
  spec.size = {radius, 0, 0};
  TriangleMesh mesh = MakeShapeMesh(spec, segments);
  for (Eigen::Vector3f& v : mesh.vertices) v.z() -= radius;
  return mesh;
}

TriangleMesh MakeRectangle(float size_x, float size_y, int cells_x, int cells_y) {
  TriangleMesh mesh;
  for (int j = 0; j <= cells_y; ++j) {
    for (int i = 0; i <= cells_x; ++i) {
      const float u = static_cast<float>(i) / cells_x, v = static_cast<float>(j) / cells_y;
      mesh.vertices.emplace_back((u - 0.5f) * size_x, (v - 0.5f) * size_y, 0.0f);
      mesh.uvs.emplace_back(u, v);
    }
  }
  for (int j = 0; j < cells_y; ++j) {
    for (int i = 0; i < cells_x; ++i) {
      const uint32_t a = j * (cells_x + 1) + i;
      AppendQuad(mesh, a, a + 1, a + cells_x + 2, a + cells_x + 1);
    }
  }
  return mesh;
}

namespace {

std::vector<Eigen::Vector2f> BottleProfile(float r, float h) {
  // Body, shoulder, neck: radius r, height h; neck radius 0.35 r over the top 25 %.
  const float neck = 0.35f * r, body = 0.6f * h, shoulder = 0.75f * h;
  std::vector<Eigen::Vector2f> profile = {{0, 0}, {r, 0}, {r, body}};
  for (int i = 1; i <= 6; ++i) {
    const float t = static_cast<float>(i) / 6.0f;
    const float s = 0.5f - 0.5f * std::cos(kPi * t);
    profile.emplace_back(r + (neck - r) * s, body + (shoulder - body) * t);
  }
  profile.push_back({neck, h});
  profile.push_back({0, h});
  return profile;
}

std::vector<Eigen::Vector2f> BowlProfile(float r, float h) {
  // Outer quarter-ellipse from the foot to the rim, inner one back down.
  const float wall = 0.08f * r;
  std::vector<Eigen::Vector2f> profile = {{0, 0}, {0.5f * r, 0}};
  for (int i = 1; i <= 8; ++i) {
    const float a = 0.5f * kPi * static_cast<float>(i) / 8.0f;
    profile.emplace_back(0.5f * r + 0.5f * r * std::sin(a), h * (1.0f - std::cos(a)));
  }
  for (int i = 8; i >= 0; --i) {
    const float a = 0.5f * kPi * static_cast<float>(i) / 8.0f;
    profile.emplace_back(std::max(0.0f, (r - wall) * std::sin(a)),
                         wall + (h - wall) * (1.0f - std::cos(a)));
  }
  profile.back().x() = 0.0f;
  return profile;
}

TriangleMesh MakeMug(const ShapeSpec& spec, int segments) {
  const float r = spec.size.x(), h = spec.size.z();
  // The cup, and a handle: a torus standing in the x-z plane at +x whose tube touches the
  // wall, sunk half the wall's thickness into it. (Until 2026-12-06 the torus stood 2 tubes
  // into the cup: its inner arc hung inside the cavity, a surface no mug has.) The handle
  // reaches 0.56 h beyond the wall, its hole 0.2 h across.
  TriangleMesh mesh = MakeShapeMesh({ShapeKind::kCup, spec.size}, segments);
  const float wall = 0.08f * r, tube = 0.09f * h, major = 0.28f * h - tube + 0.25f * wall;
  TriangleMesh handle =
      MakeShapeMesh({ShapeKind::kTorus, Eigen::Vector3f(major, tube, 0)}, segments / 2);
  Rigid3d stand;  // torus axis z -> y, centred beside the wall at mid height
  stand.rotation = Eigen::AngleAxisd(0.5 * kPi, Eigen::Vector3d::UnitX()).toRotationMatrix();
  stand.translation = Eigen::Vector3d(r - 0.5f * wall + major + tube, 0, 0.5 * h - tube);
  handle.Transform(stand);
  mesh.Append(handle);
  return mesh;
}

TriangleMesh MakeLBlock(const Eigen::Vector3f& size) {
  // A tall bar along x and a lower arm along y at one end: the two boxes share a face.
  const Eigen::Vector3f bar(size.x(), 0.4f * size.y(), size.z());
  const Eigen::Vector3f arm(0.35f * size.x(), 0.6f * size.y(), 0.55f * size.z());
  TriangleMesh mesh = MakeBox(bar);
  Rigid3d shift_bar, shift_arm;
  shift_bar.translation = Eigen::Vector3d(0, -0.3 * size.y(), 0);
  mesh.Transform(shift_bar);
  TriangleMesh side = MakeBox(arm);
  shift_arm.translation = Eigen::Vector3d(0.5 * (size.x() - arm.x()), 0.2 * size.y(), 0);
  side.Transform(shift_arm);
  mesh.Append(side);
  return mesh;
}

TriangleMesh MakeIrregular(const Eigen::Vector3f& size) {
  // A box sheared along x with height, its top slanted along x and twisted along y.
  TriangleMesh mesh = MakeBox(size);
  const Eigen::Vector3f s = size;
  for (Eigen::Vector3f& v : mesh.vertices) {
    const float tx = v.x() / s.x(), tz = v.z() / s.z();  // tx in [-0.5, 0.5], tz in [0, 1]
    v.z() *= 1.0f + 0.7f * (tx + 0.5f) * 0.5f;           // top rises towards +x
    v.x() += 0.25f * s.x() * tz;                         // shear
    v.y() += 0.3f * s.y() * tz * (tx + 0.5f);            // twist
  }
  return mesh;
}

}  // namespace

TriangleMesh MakeShapeMesh(const ShapeSpec& spec, int segments) {
  const float r = spec.size.x(), h = spec.size.z();
  std::vector<Eigen::Vector2f> profile;
  switch (spec.kind) {
    case ShapeKind::kBox:
      return MakeBox(spec.size);
    case ShapeKind::kSphere:
      profile = Arc({0, r}, r, -0.5f * kPi, 0.5f * kPi, segments / 2);
      profile.front().x() = 0.0f;
      profile.back().x() = 0.0f;
      return MakeLathe(profile, segments, false);
    case ShapeKind::kCylinder:
      return MakeLathe({{0, 0}, {r, 0}, {r, h}, {0, h}}, segments, false);
    case ShapeKind::kCone:
      return MakeLathe({{0, 0}, {r, 0}, {0, h}}, segments, false);
    case ShapeKind::kTorus: {
      const float tube = spec.size.y();
      profile = Arc({r, tube}, tube, -kPi, kPi, segments / 2);
      profile.pop_back();  // closed loop: the last point equals the first
      return MakeLathe(profile, segments, true);
    }
    case ShapeKind::kBottle:
      return MakeLathe(BottleProfile(r, h), segments, false);
    case ShapeKind::kCup: {
      const float wall = 0.08f * r;
      return MakeLathe({{0, 0}, {r, 0}, {r, h}, {r - wall, h}, {r - wall, wall}, {0, wall}},
                       segments, false);
    }
    case ShapeKind::kBowl:
      return MakeLathe(BowlProfile(r, h), segments, false);
    case ShapeKind::kMug:
      return MakeMug(spec, segments);
    case ShapeKind::kLBlock:
      return MakeLBlock(spec.size);
    case ShapeKind::kIrregular:
      return MakeIrregular(spec.size);
  }
  return {};
}

}  // namespace instascene
