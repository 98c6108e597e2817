#include <gtest/gtest.h>

#include "common/core/testing/temp_dir.h"

#include <cmath>
#include <filesystem>
#include <numbers>
#include <random>

#include "absl/strings/str_cat.h"
#include "common/splat/gaussian_cloud.h"
#include "common/splat/gaussian_ply.h"
#include "common/splat/sh.h"

namespace instascene {
namespace {

GaussianCloud RandomCloud(size_t n, int num_scales, int sh_degree, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> normal;
  GaussianCloud cloud;
  cloud.num_scales = num_scales;
  cloud.sh_degree = sh_degree;
  cloud.extras.push_back({"segfeat_0", ScalarType::kFloat32, {}});
  cloud.extras.push_back({"segfeat_1", ScalarType::kFloat32, {}});
  cloud.extras.push_back({"label", ScalarType::kUint8, {}});
  cloud.Resize(n);
  for (float& v : cloud.positions) v = normal(rng);
  for (float& v : cloud.log_scales) v = normal(rng) - 3.0f;
  for (float& v : cloud.rotations) v = normal(rng);
  for (float& v : cloud.opacity_logits) v = normal(rng);
  for (float& v : cloud.sh) v = normal(rng);
  for (size_t i = 0; i < n; ++i) {
    cloud.extras[0].values[i] = normal(rng);
    cloud.extras[1].values[i] = normal(rng);
    cloud.extras[2].values[i] = static_cast<float>(i % 7);
  }
  return cloud;
}

void ExpectSameCloud(const GaussianCloud& a, const GaussianCloud& b) {
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(a.num_scales, b.num_scales);
  EXPECT_EQ(a.sh_degree, b.sh_degree);
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.log_scales, b.log_scales);
  EXPECT_EQ(a.rotations, b.rotations);
  EXPECT_EQ(a.opacity_logits, b.opacity_logits);
  EXPECT_EQ(a.sh, b.sh);
  ASSERT_EQ(a.extras.size(), b.extras.size());
  for (size_t e = 0; e < a.extras.size(); ++e) {
    EXPECT_EQ(a.extras[e].name, b.extras[e].name);
    EXPECT_EQ(a.extras[e].type, b.extras[e].type);
    EXPECT_EQ(a.extras[e].values, b.extras[e].values);
  }
}

class PlyRoundTrip : public ::testing::TestWithParam<std::tuple<int, int>> {};

TEST_P(PlyRoundTrip, WriteThenReadIsIdentity) {
  auto [num_scales, degree] = GetParam();
  GaussianCloud cloud = RandomCloud(37, num_scales, degree, 11 + degree);
  absl::StatusOr<GaussianCloud> back = ParseGaussianPly(EncodeGaussianPly(cloud), "mem");
  ASSERT_TRUE(back.ok()) << back.status();
  ExpectSameCloud(cloud, *back);
}

INSTANTIATE_TEST_SUITE_P(ScalesAndDegrees, PlyRoundTrip,
                         ::testing::Combine(::testing::Values(2, 3),
                                            ::testing::Values(0, 1, 2, 3)));

TEST(GaussianPly, WritesAtomicallyToDisk) {
  const instascene::testing::ScopedTempDir temp("ply_roundtrip");
  const std::string dir = temp.str();
  const std::string path = dir + "/roundtrip.ply";
  GaussianCloud cloud = RandomCloud(10, 2, 1, 5);
  ASSERT_TRUE(WriteGaussianPly(path, cloud).ok());
  absl::StatusOr<GaussianCloud> back = ReadGaussianPly(path);
  ASSERT_TRUE(back.ok()) << back.status();
  ExpectSameCloud(cloud, *back);
  // An invalid cloud is refused and the earlier file stays intact.
  GaussianCloud bad = cloud;
  bad.positions[4] = std::nanf("");
  absl::Status s = WriteGaussianPly(path, bad);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("Gaussian #1"), std::string::npos) << s;
  ASSERT_TRUE(ReadGaussianPly(path).ok());
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    EXPECT_EQ(entry.path().string().find("roundtrip.ply.tmp"), std::string::npos);
  }
}

// A hand-written header with properties in an unusual order and mixed types.
std::string TinyHeader(absl::string_view format, int count) {
  return absl::StrCat("ply\nformat ", format,
                      " 1.0\ncomment test\nelement camera 1\nproperty list uchar float k\n"
                      "element vertex ",
                      count,
                      "\nproperty double rot_1\nproperty float opacity\nproperty float x\n"
                      "property float y\nproperty float z\nproperty float scale_1\n"
                      "property float scale_0\nproperty float rot_0\nproperty float rot_2\n"
                      "property float rot_3\nproperty float f_dc_2\nproperty float f_dc_1\n"
                      "property float f_dc_0\nproperty int label\nend_header\n");
}

TEST(GaussianPly, ElementCountsMustBeWholeIntegers) {
  for (const char* count : {"8e3", "8.0", "0x10", "8 9", "-1"}) {
    std::string data = TinyHeader("ascii", 2);
    data.replace(data.find("element vertex 2"), 16, std::string("element vertex ") + count);
    const absl::Status s = ParseGaussianPly(data, "counts.ply").status();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << count;
    EXPECT_NE(s.message().find("element"), std::string::npos) << s;
  }
}

// Found by ply_fuzz (tests/fuzz): an element without properties but a count of 2.2e13 before the
// wanted one made the reader loop over every declared instance of nothing.
TEST(GaussianPly, AnElementWithoutPropertiesIsSkippedWhateverItsCount) {
  for (const char* format : {"ascii", "binary_little_endian"}) {
    const std::string data = absl::StrCat("ply\nformat ", format,
                                          " 1.0\nelement chunk 22222222222222\nelement vertex "
                                          "0\nproperty float x\nend_header\n");
    absl::StatusOr<PlyHeader> header = ParsePlyHeader(data, "empty.ply");
    ASSERT_TRUE(header.ok()) << header.status();
    absl::StatusOr<PlyColumns> vertex = ReadPlyElement(data, *header, "vertex", "empty.ply");
    ASSERT_TRUE(vertex.ok()) << vertex.status();
    EXPECT_EQ(vertex->count, 0);
    absl::StatusOr<PlyColumns> chunk = ReadPlyElement(data, *header, "chunk", "empty.ply");
    ASSERT_TRUE(chunk.ok());
    EXPECT_TRUE(chunk->columns.empty());
  }
}

TEST(GaussianPly, ReadsAsciiWithAnyPropertyOrderAndSkipsOtherElements) {
  std::string data = TinyHeader("ascii", 2) +
                     "2 0.5 0.25\n"
                     "0 1.5 1 2 3 -1 -2 1 0 0 0.3 0.2 0.1 42\n"
                     "0 -1 4 5 6 -3 -4 0 1 0 0.6 0.5 0.4 -7\n";
  absl::StatusOr<GaussianCloud> cloud = ParseGaussianPly(data, "tiny.ply");
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  ASSERT_EQ(cloud->size(), 2u);
  EXPECT_EQ(cloud->num_scales, 2);
  EXPECT_EQ(cloud->sh_degree, 0);
  EXPECT_EQ(cloud->positions, (std::vector<float>{1, 2, 3, 4, 5, 6}));
  EXPECT_EQ(cloud->log_scales, (std::vector<float>{-2, -1, -4, -3}));
  EXPECT_EQ(cloud->rotations, (std::vector<float>{1, 0, 0, 0, 0, 0, 1, 0}));
  EXPECT_EQ(cloud->sh, (std::vector<float>{0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f}));
  EXPECT_EQ(cloud->opacity_logits, (std::vector<float>{1.5f, -1.0f}));
  const ExtraChannel* label = cloud->FindExtra("label");
  ASSERT_NE(label, nullptr);
  EXPECT_EQ(label->type, ScalarType::kInt32);
  EXPECT_EQ(label->values, (std::vector<float>{42, -7}));
}

void AppendBigEndian(std::string* out, const void* value, int size) {
  const char* p = static_cast<const char*>(value);
  for (int i = size - 1; i >= 0; --i) out->push_back(p[i]);
}

TEST(GaussianPly, ReadsBinaryBigEndian) {
  std::string data = TinyHeader("binary_big_endian", 1);
  data.push_back(1);  // camera list of one float
  float k = 0.5f;
  AppendBigEndian(&data, &k, 4);
  double rot1 = 0.0;
  AppendBigEndian(&data, &rot1, 8);
  const float values[] = {0.7f, 1, 2, 3, -1, -2, 1, 0, 0, 0.3f, 0.2f, 0.1f};
  for (float v : values) AppendBigEndian(&data, &v, 4);
  int32_t label = 99;
  AppendBigEndian(&data, &label, 4);
  absl::StatusOr<GaussianCloud> cloud = ParseGaussianPly(data, "be.ply");
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  EXPECT_EQ(cloud->positions, (std::vector<float>{1, 2, 3}));
  EXPECT_EQ(cloud->opacity_logits[0], 0.7f);
  EXPECT_EQ(cloud->FindExtra("label")->values[0], 99.0f);
}

void ExpectError(const std::string& data, absl::string_view fragment) {
  absl::StatusOr<GaussianCloud> cloud = ParseGaussianPly(data, "bad.ply");
  ASSERT_FALSE(cloud.ok()) << "expected an error containing: " << fragment;
  EXPECT_EQ(cloud.status().code(), absl::StatusCode::kInvalidArgument) << cloud.status();
  EXPECT_NE(cloud.status().message().find(fragment), std::string::npos) << cloud.status();
  EXPECT_NE(cloud.status().message().find("bad.ply"), std::string::npos) << cloud.status();
}

TEST(GaussianPly, BadInputGivesPreciseErrors) {
  const std::string good = EncodeGaussianPly(RandomCloud(20, 2, 1, 3));
  ExpectError(good.substr(0, good.size() - 10), "truncated");
  ExpectError(good.substr(0, 30), "end_header");
  ExpectError("hello", "not a PLY");
  std::string wrong_count = good;
  wrong_count.replace(wrong_count.find("vertex 20"), 9, "vertex 21");
  ExpectError(wrong_count, "declares 21");
  std::string missing = good;
  missing.replace(missing.find("property float opacity"), 22, "property float opacitX");
  ExpectError(missing, "'opacity'");
  // "rot_00" is not rot_0: refused, never indexed as column -1 (found by ply_fuzz).
  std::string leading_zero = good;
  leading_zero.replace(leading_zero.find("property float rot_0"), 20, "property float rot_00");
  ExpectError(leading_zero, "rot_");
  std::string bad_type = good;
  bad_type.replace(bad_type.find("property float x"), 16, "property flt   x");
  ExpectError(bad_type, "unknown property type");
  ExpectError(TinyHeader("ascii", 1) + "2 0 0\n0 nan 1 2 3 -1 -2 1 0 0 0.3 0.2 0.1 4\n",
              "Gaussian #0");
  ExpectError(TinyHeader("ascii", 2) +
                  "0\n0 1 1 2 3 -1 -2 1 0 0 0.3 0.2 0.1 4\n"
                  "0 1 1 2 3 -1 -2 0 0 0 0.3 0.2 0.1 4\n",
              "Gaussian #1: zero-norm quaternion");
  ExpectError(TinyHeader("ascii", 1) + "0\n0 1 1 2 3 -1 -2 1 0 0 0.3 abc 0.1 4\n",
              "#0 property 'f_dc_1'");
  ExpectError(TinyHeader("ascii", 1) + "0\n0 1 1 2 3 -1 -2 1 0 0 0.3 0.2 0.1 1e30\n", "'label'");
}

TEST(GaussianPly, RandomCorruptionNeverCrashes) {
  const std::string good = EncodeGaussianPly(RandomCloud(8, 3, 2, 9));
  std::mt19937 rng(17);
  for (int trial = 0; trial < 300; ++trial) {
    std::string data = good;
    const int flips = 1 + trial % 5;
    for (int f = 0; f < flips; ++f) data[rng() % data.size()] = static_cast<char>(rng());
    if (trial % 3 == 0) data.resize(rng() % data.size());
    absl::StatusOr<GaussianCloud> cloud = ParseGaussianPly(data, "fuzz.ply");
    if (cloud.ok()) {
      EXPECT_TRUE(cloud->Validate().ok());
    }
  }
}

TEST(GaussianPly, RealSplatsInBothPropertyOrdersLoadEqual) {
  const std::string dir = std::string(INSTASCENE_SHARED_DIR) + "/data/splats/";
  if (!std::filesystem::exists(dir + "playbot_lod6.ply")) GTEST_SKIP() << "shared data missing";
  absl::StatusOr<GaussianCloud> a = ReadGaussianPly(dir + "playbot_lod6.ply");
  absl::StatusOr<GaussianCloud> b = ReadGaussianPly(dir + "playbot_lod6_3dgs_order.ply");
  ASSERT_TRUE(a.ok()) << a.status();
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(a->size(), 1873u);
  EXPECT_EQ(a->sh_degree, 2);
  EXPECT_EQ(a->num_scales, 3);
  EXPECT_TRUE(a->extras.empty());
  ExpectSameCloud(*a, *b);
  absl::StatusOr<GaussianCloud> compressed =
      ReadGaussianPly(dir + "originals/guitar.compressed.ply");
  ASSERT_FALSE(compressed.ok());
  EXPECT_NE(compressed.status().message().find("compressed"), std::string::npos);
}

TEST(Sh, BasisIsOrthonormalOnTheSphere) {
  // Integrate products of the 16 basis functions (each picked by a unit coefficient) with a
  // Fibonacci-sphere quadrature: the result must be the identity (checks every constant).
  constexpr int kPoints = 20000;
  double gram[16][16] = {};
  std::vector<float> coeffs(16 * 3);
  for (int p = 0; p < kPoints; ++p) {
    const double z = 1.0 - (2.0 * p + 1.0) / kPoints;
    const double r = std::sqrt(1.0 - z * z);
    const double phi = p * std::numbers::pi * (3.0 - std::sqrt(5.0));
    const float x = static_cast<float>(r * std::cos(phi)),
                y = static_cast<float>(r * std::sin(phi));
    double basis[16];
    for (int k = 0; k < 16; ++k) {
      std::fill(coeffs.begin(), coeffs.end(), 0.0f);
      coeffs[0] = 100.0f;  // a large DC term keeps the result positive: the clamp never triggers
      coeffs[3 * k] += 1.0f;
      float rgb[3];
      EvalShColor(3, coeffs.data(), x, y, static_cast<float>(z), rgb);
      basis[k] = rgb[0] - 0.5 - 100.0 * kShC0;
    }
    for (int i = 0; i < 16; ++i) {
      for (int j = 0; j < 16; ++j)
        gram[i][j] += basis[i] * basis[j] * 4.0 * std::numbers::pi / kPoints;
    }
  }
  for (int i = 0; i < 16; ++i) {
    for (int j = 0; j < 16; ++j) {
      EXPECT_NEAR(gram[i][j], i == j ? 1.0 : 0.0, 5e-3) << i << "," << j;
    }
  }
}

TEST(Sh, ClampsAtZeroOnly) {
  float coeffs[3] = {-10.0f, 0.0f, 10.0f};
  float rgb[3];
  EvalShColor(0, coeffs, 0, 0, 1, rgb);
  EXPECT_EQ(rgb[0], 0.0f);
  EXPECT_FLOAT_EQ(rgb[1], 0.5f);
  EXPECT_FLOAT_EQ(rgb[2], 0.5f + 10.0f * kShC0);  // above 1: no upper clamp
}

TEST(ToSurfels, DropsSmallestAxisAndKeepsFrame) {
  GaussianCloud cloud = RandomCloud(50, 3, 0, 21);
  GaussianCloud surfels = ToSurfels(cloud);
  ASSERT_EQ(surfels.num_scales, 2);
  ASSERT_TRUE(surfels.Validate().ok());
  for (size_t i = 0; i < cloud.size(); ++i) {
    const float* s = &cloud.log_scales[3 * i];
    std::vector<float> sorted(s, s + 3);
    std::sort(sorted.begin(), sorted.end());
    std::vector<float> kept = {surfels.log_scales[2 * i], surfels.log_scales[2 * i + 1]};
    std::sort(kept.begin(), kept.end());
    EXPECT_EQ(kept[0], sorted[1]);
    EXPECT_EQ(kept[1], sorted[2]);
  }
}

}  // namespace
}  // namespace instascene

namespace instascene {
namespace {

TEST(RobustBounds, MatchesSortedPercentilesAndIgnoresFloaters) {
  GaussianCloud cloud;
  cloud.Resize(1000);
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (float& p : cloud.positions) p = u(rng);
  for (int i = 0; i < 5; ++i) cloud.positions[3 * i] = 1000.0f;  // far floaters on x
  const Eigen::AlignedBox3f box = RobustBounds(cloud);
  for (int a = 0; a < 3; ++a) {
    std::vector<float> v(cloud.size());
    for (size_t i = 0; i < cloud.size(); ++i) v[i] = cloud.positions[3 * i + a];
    std::sort(v.begin(), v.end());
    EXPECT_EQ(box.min()[a], v[20]);
    EXPECT_EQ(box.max()[a], v[980]);
  }
  EXPECT_LT(box.max().x(), 1.0f);
  EXPECT_TRUE(RobustBounds(GaussianCloud{}).isEmpty());
}

}  // namespace
}  // namespace instascene
