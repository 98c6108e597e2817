// Export of objects for robot stacks: mass properties against analytic values and brute-force
// integration, Qhull hulls, the convex decomposition of a cup, Draco glTF, and the exported files
// read by tools nobody here wrote: urdfdom's check_urdf and MuJoCo (a drop onto a plane).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>

#include "absl/strings/str_cat.h"
#include "common/core/file_io.h"
#include "common/core/testing/temp_dir.h"
#include "common/mesh/mesh_checks.h"
#include "common/mesh/mesh_ply.h"
#include "common/store/digest.h"
#include "services/objects/convex_decomposition.h"
#include "services/objects/convex_hull.h"
#include "services/objects/export.h"
#include "services/objects/gltf_writer.h"
#include "services/objects/mass_properties.h"
#include "services/objects/testing/mujoco_drop.h"
#include "services/objects/testing/shapes.h"

namespace instascene::objects {
namespace {
namespace fs = std::filesystem;

TriangleMesh Box(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
  TriangleMesh m;
  for (int c = 0; c < 8; ++c)
    m.vertices.emplace_back(c & 1 ? hi.x() : lo.x(), c & 2 ? hi.y() : lo.y(),
                            c & 4 ? hi.z() : lo.z());
  auto hull = ConvexHull(m.vertices);
  EXPECT_TRUE(hull.ok());
  return *hull;
}

using testing::Cup;

TEST(MassPropertiesTest, BoxMatchesClosedForm) {
  const MassProperties m = MeshMassProperties(Box({0, 0, 0}, {2, 1, 3}), 10.0);
  EXPECT_NEAR(m.volume, 6.0, 1e-9);
  EXPECT_NEAR(m.mass, 60.0, 1e-9);
  EXPECT_TRUE(m.center.isApprox(Eigen::Vector3d(1, 0.5, 1.5), 1e-9));
  // I_xx = m (b² + c²) / 12 for a box of sides a, b, c.
  EXPECT_NEAR(m.inertia(0, 0), 60.0 * (1 + 9) / 12, 1e-7);
  EXPECT_NEAR(m.inertia(1, 1), 60.0 * (4 + 9) / 12, 1e-7);
  EXPECT_NEAR(m.inertia(2, 2), 60.0 * (4 + 1) / 12, 1e-7);
  EXPECT_NEAR(m.inertia(0, 1), 0, 1e-7);
  // Two boxes side by side are one box (parallel-axis theorem).
  const MassProperties c = Combine({MeshMassProperties(Box({0, 0, 0}, {1, 1, 3}), 10.0),
                                    MeshMassProperties(Box({1, 0, 0}, {2, 1, 3}), 10.0)});
  EXPECT_NEAR(c.mass, m.mass, 1e-9);
  EXPECT_TRUE(c.inertia.isApprox(m.inertia, 1e-9));
}

TEST(MassPropertiesTest, RandomPolytopeMatchesBruteForceIntegration) {
  std::mt19937 rng(5);
  std::normal_distribution<float> g(0.f, 1.f);
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < 40; ++i) points.emplace_back(1.5f * g(rng) + 3, g(rng) - 1, 0.7f * g(rng));
  auto hull = ConvexHull(points);
  ASSERT_TRUE(hull.ok()) << hull.status();
  const MassProperties exact = MeshMassProperties(*hull);
  Eigen::AlignedBox3f box;
  for (const auto& v : hull->vertices) box.extend(v);
  const int n = 70;
  const Eigen::Vector3d step = box.sizes().cast<double>() / n;
  double volume = 0;
  Eigen::Vector3d first = Eigen::Vector3d::Zero();
  Eigen::Matrix3d second = Eigen::Matrix3d::Zero();
  const double dv = step.prod();
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const Eigen::Vector3d x = box.min().cast<double>() +
                                  step.cwiseProduct(Eigen::Vector3d(i + 0.5, j + 0.5, k + 0.5));
        if (HullSignedDistance(*hull, x.cast<float>()) > 0) continue;
        volume += dv;
        first += dv * x;
        second += dv * x * x.transpose();
      }
  const Eigen::Vector3d com = first / volume;
  const Eigen::Matrix3d c = second - volume * com * com.transpose();
  const Eigen::Matrix3d inertia = c.trace() * Eigen::Matrix3d::Identity() - c;
  EXPECT_NEAR(exact.volume, volume, 0.02 * volume);
  EXPECT_LT((exact.center - com).norm(), 0.01 * box.sizes().norm());
  EXPECT_LT((exact.inertia - inertia).norm(), 0.04 * inertia.norm());
}

TEST(ConvexHullTest, ContainsEveryPointIsClosedAndRefusesFlatInput) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < 500; ++i) points.emplace_back(u(rng), u(rng), u(rng));
  auto hull = ConvexHull(points);
  ASSERT_TRUE(hull.ok()) << hull.status();
  EXPECT_TRUE(IsClosedManifold(*hull));
  EXPECT_LT(hull->vertices.size(), points.size());
  for (const auto& p : points) EXPECT_LE(HullSignedDistance(*hull, p), 1e-5f);
  EXPECT_GT(MeshMassProperties(*hull).volume, 0);
  std::vector<Eigen::Vector3f> flat;
  for (int i = 0; i < 20; ++i) flat.emplace_back(u(rng), u(rng), 0.f);
  EXPECT_EQ(ConvexHull(flat).status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(ConvexHull({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}).status().code(),
            absl::StatusCode::kFailedPrecondition);
}

TEST(ConvexDecompositionTest, ACupKeepsItsCavityAndABoxStaysOnePart) {
  const TriangleMesh cup = Cup();
  ASSERT_TRUE(IsClosedManifold(cup));
  const double cup_volume = MeshMassProperties(cup).volume;
  EXPECT_NEAR(cup_volume, M_PI * (2.0 - 0.64 * 1.8), 0.02 * cup_volume);  // faceting
  auto parts = ConvexDecomposition(cup);
  ASSERT_TRUE(parts.ok()) << parts.status();
  EXPECT_GE(parts->size(), 3u);
  EXPECT_LE(parts->size(), 12u);
  double total = 0;
  for (const TriangleMesh& p : *parts) {
    EXPECT_TRUE(IsClosedManifold(p));
    total += MeshMassProperties(p).volume;
    // The cavity stays empty: its axis, from near the bottom to the rim.
    for (float z : {-0.6f, 0.0f, 0.9f}) EXPECT_GT(HullSignedDistance(p, {0, 0, z}), 0.1f) << z;
  }
  EXPECT_LT(total, 1.6 * cup_volume);
  EXPECT_GT(total, 0.9 * cup_volume);
  // Every surface point of the cup is covered by some part (within a voxel).
  for (size_t v = 0; v < cup.vertices.size(); v += 7) {
    float best = 1e9f;
    for (const TriangleMesh& p : *parts)
      best = std::min(best, HullSignedDistance(p, cup.vertices[v]));
    EXPECT_LT(best, 0.06f) << v;
  }
  auto box = ConvexDecomposition(Box({0, 0, 0}, {1, 2, 0.5f}));
  ASSERT_TRUE(box.ok());
  EXPECT_EQ(box->size(), 1u);
}

TEST(GlbTest, DracoGlbIsWellFormedAndDecodesToTheSameTriangles) {
  TriangleMesh cup = Cup();
  for (const auto& v : cup.vertices) cup.colors.emplace_back(0.5f + 0.5f * v.x(), 0.2f, 0.9f);
  auto glb = EncodeDracoGlb(cup);
  ASSERT_TRUE(glb.ok()) << glb.status();
  ASSERT_GE(glb->bytes.size(), 28u);
  EXPECT_EQ(glb->bytes.substr(0, 4), "glTF");
  uint32_t version, length, json_length;
  std::memcpy(&version, glb->bytes.data() + 4, 4);
  std::memcpy(&length, glb->bytes.data() + 8, 4);
  std::memcpy(&json_length, glb->bytes.data() + 12, 4);
  EXPECT_EQ(version, 2u);
  EXPECT_EQ(length, glb->bytes.size());
  const auto gltf = nlohmann::json::parse(glb->bytes.substr(20, json_length));
  EXPECT_EQ(gltf["extensionsRequired"][0], "KHR_draco_mesh_compression");
  EXPECT_EQ(gltf["accessors"][0]["count"], glb->vertices);
  auto decoded = DecodeDraco(glb->draco);
  ASSERT_TRUE(decoded.ok());
  EXPECT_EQ(decoded->triangles.size(), cup.triangles.size());
  EXPECT_EQ(glb->triangles, cup.triangles.size());
  EXPECT_EQ(decoded->colors.size(), decoded->vertices.size());
}

// A completed object as the `complete` stage leaves it: a cup in the scene frame, posed.
std::string WriteCompletedCup(const std::string& dir, Eigen::Isometry3d* world_from_object) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.translation() = Eigen::Vector3d(3, -2, 1.5);
  *world_from_object = pose;
  TriangleMesh cup = Cup();
  for (auto& v : cup.vertices) {
    cup.colors.emplace_back(0.8f, 0.3f, 0.1f);
    v = (pose * v.cast<double>()).cast<float>();
  }
  fs::create_directories(dir);
  EXPECT_TRUE(WriteMeshPly(dir + "/mesh.ply", cup).ok());
  nlohmann::json rows = nlohmann::json::array();
  for (int r = 0; r < 3; ++r)
    rows.push_back(
        {pose.linear()(r, 0), pose.linear()(r, 1), pose.linear()(r, 2), pose.translation()(r)});
  const nlohmann::json manifest = {{"format", "instascene.object/1"},
                                   {"id", 7},
                                   {"world_from_object", rows},
                                   {"prior", "geometric"},
                                   {"abstained", false},
                                   {"gaussians", {{"completed_share", 0.25}}}};
  EXPECT_TRUE(WriteFileAtomically(dir + "/manifest.json", manifest.dump()).ok());
  return dir;
}

TEST(ExportTest, ArtefactsAreMetricPosedAndReadByCheckUrdfAndMuJoCo) {
  const instascene::testing::ScopedTempDir temp("export");
  Eigen::Isometry3d pose;
  const std::string object = WriteCompletedCup(temp.str() + "/object", &pose);
  const std::string out = temp.str() + "/export";
  ExportOptions options;
  auto manifest = ExportObject(object, {0.1, "test"}, options, out);
  ASSERT_TRUE(manifest.ok()) << manifest.status();
  const auto& m = *manifest;
  EXPECT_EQ(m["units"], "metres");
  // The cup is 0.2 m wide and tall; placed at the pose's translation, in metres.
  const auto extent = m["bounding_box"]["extent"];
  EXPECT_NEAR(extent[0].get<double>(), 0.2, 0.005);
  EXPECT_NEAR(extent[2].get<double>(), 0.2, 0.005);
  EXPECT_NEAR(m["world_from_object"]["translation"][0].get<double>(), 0.3, 1e-6);
  const auto q = m["world_from_object"]["quaternion_xyzw"];
  EXPECT_NEAR(q[2].get<double>(), std::sin(0.25), 1e-6);
  EXPECT_NEAR(q[3].get<double>(), std::cos(0.25), 1e-6);
  EXPECT_GE(m["collision"]["parts"].size(), 3u);
  // Every artefact's digest is the file's.
  for (const auto& [file, info] : m["artefacts"].items()) {
    auto bytes = ReadFileBounded(out + "/" + file, 1 << 30);
    ASSERT_TRUE(bytes.ok()) << file;
    EXPECT_EQ(store::ComputeDigest(*bytes).hash, info["sha256"]) << file;
  }
  // Mass: density × the collision parts' volume, a little above the cup's own.
  const double mass = m["inertial"]["mass"].get<double>();
  const double cup_volume = M_PI * (2.0 - 0.64 * 1.8) * 1e-3;
  EXPECT_GT(mass, 0.9 * options.density * cup_volume);
  EXPECT_LT(mass, 1.6 * options.density * cup_volume);

  // check_urdf (urdfdom) parses the URDF.
  const std::string check =
      absl::StrCat("check_urdf '", out, "/object.urdf' > '", temp.str(), "/check_urdf.txt' 2>&1");
  EXPECT_EQ(std::system(check.c_str()), 0)
      << *ReadFileBounded(temp.str() + "/check_urdf.txt", 1 << 20);

  // MuJoCo loads the MJCF inside a scene with a floor; dropped from 5 cm the cup rests upright on
  // its bottom within a simulated second, without exploding or tunnelling.
  auto drop = testing::DropOntoFloor(out + "/object.xml");
  ASSERT_TRUE(drop.ok()) << drop.status();
  EXPECT_TRUE(drop->finite);
  EXPECT_LT(drop->final_speed, 0.02) << "still moving after 1 s";
  EXPECT_LT(drop->final_spin, 0.2);
  EXPECT_GT(drop->lowest, -0.01) << "tunnelled into the floor";
  EXPECT_NEAR(drop->rest_height, 0.0, 0.005) << "not resting on the floor";
}

TEST(ExportTest, UnscaledScenesSaySoAndBadInputsAreNamed) {
  const instascene::testing::ScopedTempDir temp("export_unscaled");
  Eigen::Isometry3d pose;
  const std::string object = WriteCompletedCup(temp.str() + "/object", &pose);
  auto manifest = ExportObject(object, {std::nullopt, ""}, ExportOptions{}, temp.str() + "/out");
  ASSERT_TRUE(manifest.ok()) << manifest.status();
  EXPECT_EQ((*manifest)["units"], "scene units (unscaled)");
  EXPECT_FALSE((*manifest)["scale"]["scaled"].get<bool>());
  EXPECT_NEAR((*manifest)["bounding_box"]["extent"][2].get<double>(), 2.0, 0.05);
  ASSERT_TRUE(WriteFileAtomically(object + "/manifest.json", "{\"world_from_object\": [1]}").ok());
  const auto bad = ExportObject(object, {1.0, ""}, ExportOptions{}, temp.str() + "/out2");
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(bad.status().message().find("manifest.json"), std::string::npos);
  EXPECT_EQ(ExportObject(temp.str() + "/none", {1.0, ""}, ExportOptions{}, temp.str() + "/o3")
                .status()
                .code(),
            absl::StatusCode::kNotFound);
}

}  // namespace
}  // namespace instascene::objects
