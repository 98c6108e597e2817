// The splat formats users' tools export: each decoder on bytes built here by the format's own rules
// (hand-packed compressed-PLY words, .splat records, spz v3 gzip and v4 zstd files), so that every
// field's decoding is checked against a value known in advance; plus hostile inputs. The
// cross-check against files @playcanvas/splat-transform wrote is tests/splat_formats_test.sh.
#include <gtest/gtest.h>
#include <zlib.h>
#include <zstd.h>

#include <cmath>
#include <cstring>
#include <random>

#include "absl/strings/str_cat.h"
#include "common/splat/splat_formats.h"

namespace instascene {
namespace {

constexpr double kShC0 = 0.28209479177387814;

template <typename T>
void Put(std::string* out, T v) {
  out->append(reinterpret_cast<const char*>(&v), sizeof(T));
}

GaussianCloud RandomCloud(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> normal;
  GaussianCloud cloud;
  cloud.num_scales = 3;
  cloud.sh_degree = 0;
  cloud.Resize(n);
  for (float& v : cloud.positions) v = normal(rng);
  for (float& v : cloud.log_scales) v = normal(rng) - 3.0f;
  for (float& v : cloud.rotations) v = normal(rng);
  for (float& v : cloud.opacity_logits) v = normal(rng);
  for (float& v : cloud.sh) v = 0.5f * normal(rng);
  return cloud;
}

TEST(SplatFormats, DotSplatRoundTripsWithinItsQuantisation) {
  const GaussianCloud cloud = RandomCloud(200, 1);
  const std::string bytes = EncodeSplat(cloud);
  ASSERT_EQ(bytes.size(), 200u * 32);
  auto back = ParseSplatFile(bytes, "x.splat");
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*DetectSplatFormat(bytes, "x.splat"), SplatFormat::kSplat);
  EXPECT_EQ(*SplatCount(bytes, bytes.size(), "x.splat"), 200);
  for (size_t i = 0; i < cloud.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      EXPECT_EQ(back->positions[3 * i + a], cloud.positions[3 * i + a]);
      EXPECT_NEAR(back->log_scales[3 * i + a], cloud.log_scales[3 * i + a], 1e-5);
      const double colour = std::clamp(0.5 + kShC0 * cloud.sh[3 * i + a], 0.0, 1.0);
      EXPECT_NEAR(0.5 + kShC0 * back->sh[3 * i + a], colour, 0.5 / 255 + 1e-6);
    }
    const double alpha = 1 / (1 + std::exp(-cloud.opacity_logits[i]));
    EXPECT_NEAR(1 / (1 + std::exp(-back->opacity_logits[i])), alpha, 0.5 / 255 + 1e-6);
    // Quaternions equal up to the 8-bit step, and sign.
    const float* q = &cloud.rotations[4 * i];
    const float* r = &back->rotations[4 * i];
    const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    double dot = 0;
    for (int a = 0; a < 4; ++a) dot += q[a] / n * r[a];
    EXPECT_GT(std::abs(dot), 0.999) << i;
  }
}

TEST(SplatFormats, DotSplatRefusesBadSizesAndScales) {
  EXPECT_FALSE(ParseSplatFile(std::string(33, '\0'), "a.splat").ok());
  EXPECT_FALSE(ParseSplatFile("", "a.splat").ok());
  std::string bytes = EncodeSplat(RandomCloud(2, 2));
  const float negative = -1;
  std::memcpy(&bytes[32 + 16], &negative, 4);
  auto bad = ParseSplatFile(bytes, "a.splat");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("Gaussian 1"), std::string::npos) << bad.status();
  EXPECT_FALSE(DetectSplatFormat("garbage", "a.bin").ok());
}

// A compressed PLY of two splats whose packed words are written by hand.
std::string CompressedPly(uint32_t alpha_byte) {
  std::string s =
      "ply\nformat binary_little_endian 1.0\nelement chunk 1\n"
      "property float min_x\nproperty float min_y\nproperty float min_z\n"
      "property float max_x\nproperty float max_y\nproperty float max_z\n"
      "property float min_scale_x\nproperty float min_scale_y\nproperty float min_scale_z\n"
      "property float max_scale_x\nproperty float max_scale_y\nproperty float max_scale_z\n"
      "element vertex 2\nproperty uint packed_position\nproperty uint packed_rotation\n"
      "property uint packed_scale\nproperty uint packed_color\nend_header\n";
  for (float v : {0.f, 10.f, -4.f, 2.f, 20.f, 4.f, -5.f, -5.f, -5.f, -1.f, -3.f, -2.f}) Put(&s, v);
  // Splat 0: every field at its minimum, identity rotation (w largest, others 0.5 = 0).
  Put(&s, uint32_t{0});
  Put(&s, (uint32_t{0} << 30) | (511u << 20) | (511u << 10) | 511u);
  Put(&s, uint32_t{0});
  Put(&s, (uint32_t{0} << 24) | (uint32_t{255} << 16) | (uint32_t{0} << 8) | alpha_byte);
  // Splat 1: every field at its maximum; z largest, x = y = w = 0.
  Put(&s, 0xffffffffu);
  Put(&s, (uint32_t{3} << 30) | (511u << 20) | (511u << 10) | 511u);
  Put(&s, 0xffffffffu);
  Put(&s, 0x80808080u);
  return s;
}

TEST(SplatFormats, CompressedPlyUnpacksEveryField) {
  const std::string file = CompressedPly(128);
  EXPECT_EQ(*DetectSplatFormat(file, "a.ply"), SplatFormat::kCompressedPly);
  EXPECT_EQ(*SplatCount(file, file.size(), "a.ply"), 2);
  auto cloud = ParseSplatFile(file, "a.ply");
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  ASSERT_EQ(cloud->size(), 2u);
  EXPECT_EQ(cloud->num_scales, 3);
  // Positions and log-scales: the chunk's minimum and maximum.
  for (int a = 0; a < 3; ++a) {
    EXPECT_FLOAT_EQ(cloud->positions[a], (std::array<float, 3>{0, 10, -4})[a]);
    EXPECT_FLOAT_EQ(cloud->positions[3 + a], (std::array<float, 3>{2, 20, 4})[a]);
    EXPECT_FLOAT_EQ(cloud->log_scales[a], -5);
    EXPECT_FLOAT_EQ(cloud->log_scales[3 + a], (std::array<float, 3>{-1, -3, -2})[a]);
  }
  // 511/1023 is just under 0.5: the small components are -0.0007 * sqrt(2).
  const float small = static_cast<float>((511.0 / 1023 - 0.5) * std::sqrt(2.0));
  EXPECT_NEAR(cloud->rotations[0], 1, 1e-5);  // w
  EXPECT_NEAR(cloud->rotations[1], small, 1e-6);
  EXPECT_NEAR(cloud->rotations[7], 1, 1e-5);  // splat 1: rot_3 (z) largest
  EXPECT_NEAR(cloud->rotations[4], small, 1e-6);
  // Colour: 0 and 1 as SH DC; alpha 128/255 as its logit.
  EXPECT_NEAR(cloud->sh[0], -0.5 / kShC0, 1e-5);
  EXPECT_NEAR(cloud->sh[1], 0.5 / kShC0, 1e-5);
  EXPECT_NEAR(cloud->opacity_logits[0], std::log((128.0 / 255) / (127.0 / 255)), 1e-5);
}

TEST(SplatFormats, OpaqueAndTransparentAlphasLoadAsWhatTheyMean) {
  auto opaque = ParseSplatFile(CompressedPly(255), "a.ply");
  ASSERT_TRUE(opaque.ok()) << opaque.status();
  EXPECT_EQ(1 / (1 + std::exp(-opaque->opacity_logits[0])), 1.0f);
  auto transparent = ParseSplatFile(CompressedPly(0), "a.ply");
  ASSERT_TRUE(transparent.ok()) << transparent.status();
  EXPECT_LT(1 / (1 + std::exp(-transparent->opacity_logits[0])), 1e-8);
  // The same in an Inria PLY: +inf / -inf logits as splat-transform writes them; NaN refused.
  GaussianCloud cloud = RandomCloud(3, 3);
  std::string ply = EncodeGaussianPly(cloud);
  auto patch = [&](float value) {
    GaussianCloud c = cloud;
    std::string bytes = EncodeGaussianPly(c);
    // Find the opacity of Gaussian 1 by re-encoding with a marker value.
    c.opacity_logits[1] = 12345.5f;
    const std::string marked = EncodeGaussianPly(c);
    for (size_t i = 0; i + 4 <= marked.size(); ++i) {
      float v;
      std::memcpy(&v, &marked[i], 4);
      if (v == 12345.5f) std::memcpy(&bytes[i], &value, 4);
    }
    return bytes;
  };
  auto inf = ParseSplatFile(patch(INFINITY), "a.ply");
  ASSERT_TRUE(inf.ok()) << inf.status();
  EXPECT_EQ(inf->opacity_logits[1], kOpaqueLogit);
  auto minus = ParseSplatFile(patch(-INFINITY), "a.ply");
  ASSERT_TRUE(minus.ok()) << minus.status();
  EXPECT_EQ(minus->opacity_logits[1], -kOpaqueLogit);
  auto nan = ParseSplatFile(patch(NAN), "a.ply");
  ASSERT_FALSE(nan.ok());
  EXPECT_NE(nan.status().message().find("1"), std::string::npos);
}

TEST(SplatFormats, CompressedPlyRefusesInconsistentFiles) {
  std::string file = CompressedPly(10);
  EXPECT_FALSE(ParseSplatFile(file.substr(0, file.size() - 3), "a.ply").ok());  // truncated
  std::string chunks = file;
  chunks.replace(chunks.find("element chunk 1"), 15, "element chunk 2");
  EXPECT_FALSE(ParseSplatFile(chunks, "a.ply").ok());
}

// spz attribute streams of one splat, in file order; known values after decoding.
std::vector<std::string> SpzStreams(int version) {
  std::string positions;
  for (int32_t v : {4096, -4096, 2048}) {  // 12 fractional bits: 1, -1, 0.5
    const uint32_t u = static_cast<uint32_t>(v) & 0xffffffu;
    positions += {static_cast<char>(u & 0xff), static_cast<char>((u >> 8) & 0xff),
                  static_cast<char>((u >> 16) & 0xff)};
  }
  const std::string alphas(1, static_cast<char>(255));
  const std::string colors = {static_cast<char>(128), static_cast<char>(0), static_cast<char>(255)};
  const std::string scales = {static_cast<char>(160), static_cast<char>(80), static_cast<char>(0)};
  std::string rotations;
  if (version >= 3) {
    // Largest w (index 3); x = +mag 511 (max), y = 0, z = -0 (sign only): x = 1/sqrt2.
    uint32_t comp = 3u << 30;
    comp |= (511u) << 20;  // x (k = 0, written last, so in the top bits)
    comp |= 0u << 10;      // y
    comp |= 0u;            // z
    for (int b = 0; b < 4; ++b) rotations += static_cast<char>((comp >> (8 * b)) & 0xff);
  } else {
    rotations = {static_cast<char>(255), static_cast<char>(128), static_cast<char>(128)};
  }
  std::string sh;  // degree 1: 3 coefficients x RGB; coefficient j channel c = 128 + 64
  for (int j = 0; j < 3; ++j)
    for (int c = 0; c < 3; ++c) sh += static_cast<char>(192);
  return {positions, alphas, colors, scales, rotations, sh};
}

void ExpectKnownSpz(const GaussianCloud& c, int version) {
  ASSERT_EQ(c.size(), 1u);
  // RUB -> RDF: y and z negated.
  EXPECT_FLOAT_EQ(c.positions[0], 1);
  EXPECT_FLOAT_EQ(c.positions[1], 1);
  EXPECT_FLOAT_EQ(c.positions[2], -0.5f);
  EXPECT_FLOAT_EQ(c.log_scales[0], 0);
  EXPECT_FLOAT_EQ(c.log_scales[1], -5);
  EXPECT_FLOAT_EQ(c.log_scales[2], -10);
  EXPECT_NEAR(c.sh[0], (128 / 255.0 - 0.5) / 0.15, 1e-5);
  EXPECT_NEAR(c.sh[1], -0.5 / 0.15, 1e-5);
  EXPECT_EQ(1 / (1 + std::exp(-c.opacity_logits[0])), 1.0f);
  if (version >= 3) {
    EXPECT_NEAR(c.rotations[1], M_SQRT1_2, 1e-6);  // x kept
    EXPECT_NEAR(c.rotations[0], M_SQRT1_2, 1e-6);  // w
  } else {
    EXPECT_NEAR(c.rotations[1], 255 / 127.5 - 1, 1e-6);
  }
  // SH degree 1 flips for RUB -> RDF: (-1, -1, +1).
  EXPECT_NEAR(c.sh[3], -0.5, 1e-6);
  EXPECT_NEAR(c.sh[6], -0.5, 1e-6);
  EXPECT_NEAR(c.sh[9], 0.5, 1e-6);
}

std::string SpzHeader16(int version) {
  std::string h;
  Put(&h, uint32_t{0x5053474e});
  Put(&h, uint32_t(version));
  Put(&h, uint32_t{1});
  h += {static_cast<char>(1), static_cast<char>(12), static_cast<char>(0), static_cast<char>(0)};
  return h;
}

std::string Gzip(const std::string& raw) {
  z_stream z{};
  deflateInit2(&z, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY);
  std::string out(deflateBound(&z, raw.size()) + 64, '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(raw.data()));
  z.avail_in = raw.size();
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = out.size();
  deflate(&z, Z_FINISH);
  out.resize(z.total_out);
  deflateEnd(&z);
  return out;
}

TEST(SplatFormats, SpzVersions2And3InGzip) {
  for (int version : {2, 3}) {
    std::string raw = SpzHeader16(version);
    for (const std::string& s : SpzStreams(version)) raw += s;
    const std::string file = Gzip(raw);
    EXPECT_EQ(*DetectSplatFormat(file, "a.spz"), SplatFormat::kSpz);
    EXPECT_EQ(*SplatCount(file, file.size(), "a.spz"), 1);
    auto cloud = ParseSplatFile(file, "a.spz");
    ASSERT_TRUE(cloud.ok()) << cloud.status();
    ExpectKnownSpz(*cloud, version);
    EXPECT_FALSE(ParseSplatFile(file.substr(0, file.size() / 2), "a.spz").ok()) << version;
  }
}

TEST(SplatFormats, SpzVersion4WithZstdStreams) {
  const std::vector<std::string> streams = SpzStreams(4);
  std::string header;
  Put(&header, uint32_t{0x5053474e});
  Put(&header, uint32_t{4});
  Put(&header, uint32_t{1});
  header +=
      {static_cast<char>(1), static_cast<char>(12), static_cast<char>(0), static_cast<char>(6)};
  Put(&header, uint32_t{32});
  header.append(12, '\0');
  std::string toc, body;
  for (const std::string& s : streams) {
    std::string z(ZSTD_compressBound(s.size()), '\0');
    z.resize(ZSTD_compress(z.data(), z.size(), s.data(), s.size(), 3));
    Put(&toc, uint64_t(z.size()));
    Put(&toc, uint64_t(s.size()));
    body += z;
  }
  const std::string file = header + toc + body;
  EXPECT_EQ(*SplatCount(file, file.size(), "a.spz"), 1);
  auto cloud = ParseSplatFile(file, "a.spz");
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  ExpectKnownSpz(*cloud, 4);
  // A table that lies about a stream's size, and a huge point count, are refused.
  std::string lying = file;
  const uint64_t wrong = 999;
  std::memcpy(&lying[32 + 8], &wrong, 8);
  EXPECT_FALSE(ParseSplatFile(lying, "a.spz").ok());
  std::string huge = file;
  const uint32_t many = 0xffffffffu;
  std::memcpy(&huge[8], &many, 4);
  EXPECT_FALSE(ParseSplatFile(huge, "a.spz").ok());
}

}  // namespace
}  // namespace instascene
