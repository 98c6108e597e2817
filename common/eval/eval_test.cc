#include <gtest/gtest.h>

#include "common/core/testing/temp_dir.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <numbers>
#include <random>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "common/core/file_io.h"
#include "common/eval/click_eval.h"
#include "common/eval/geometry_metrics.h"
#include "common/eval/metrics.h"
#include "common/eval/result.h"
#include "common/raster/label_render.h"
#include "common/synth/primitives.h"
#include "common/synth/scene_writer.h"

namespace instascene {
namespace {

TEST(Metrics, MaskIouByHand) {
  const std::vector<uint32_t> a = {1, 1, 0, 2, 1}, b = {1, 0, 0, 1, 3};
  EXPECT_DOUBLE_EQ(MaskIou(a, 1, b, 1), 1.0 / 4.0);  // inter {0}, union {0, 1, 3, 4}
  EXPECT_DOUBLE_EQ(MaskIou(a, 9, b, 9), 0.0);
}

// Pair-counting form of the ARI (Hubert & Arabie), O(n^2): an independent reference.
double PairCountingAri(const std::vector<uint32_t>& a, const std::vector<uint32_t>& b) {
  double n11 = 0, n10 = 0, n01 = 0, n00 = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    for (size_t j = i + 1; j < a.size(); ++j) {
      const bool sa = a[i] == a[j], sb = b[i] == b[j];
      n11 += sa && sb;
      n10 += sa && !sb;
      n01 += !sa && sb;
      n00 += !sa && !sb;
    }
  }
  return 2.0 * (n00 * n11 - n01 * n10) / ((n00 + n01) * (n01 + n11) + (n00 + n10) * (n10 + n11));
}

TEST(Metrics, AdjustedRandIndexMatchesPairCounting) {
  EXPECT_NEAR(AdjustedRandIndex({0, 0, 1, 1}, {0, 0, 1, 2}), 0.5714285714285714,
              1e-12);  // sklearn's example
  EXPECT_DOUBLE_EQ(AdjustedRandIndex({3, 3, 5, 5, 7}, {1, 1, 0, 0, 9}),
                   1.0);  // same partition, other ids
  std::mt19937 rng(4);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<uint32_t> a(80), b(80);
    for (size_t i = 0; i < a.size(); ++i) {
      a[i] = rng() % 5;
      b[i] = trial % 2 ? a[i] * 2 + (rng() % 7 == 0) : rng() % 4;
    }
    EXPECT_NEAR(AdjustedRandIndex(a, b), PairCountingAri(a, b), 1e-9);
  }
}

TEST(Metrics, InstanceMatchingByHand) {
  // GT: A = {0..3}, B = {4..7}, C = {8, 9}; prediction merges A and B, finds C, adds a spurious D.
  const std::vector<uint32_t> gt = {1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 0, 0};
  const std::vector<uint32_t> pred = {5, 5, 5, 5, 5, 5, 5, 5, 6, 6, 7, 7};
  const InstanceMatch m = MatchInstances(pred, gt);
  EXPECT_EQ(m.ground_truth, 3);
  EXPECT_EQ(m.predicted, 3);
  EXPECT_EQ(m.matched, 1);
  EXPECT_DOUBLE_EQ(m.recall, 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(m.precision, 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(m.best_iou.at(1), 0.5);  // 4 / 8: not above 0.5
  EXPECT_DOUBLE_EQ(m.mean_best_iou, (0.5 + 0.5 + 1.0) / 3.0);
}

Image RandomImage(int w, int h, int c, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0, 1);
  Image img{w, h, c, std::vector<float>(static_cast<size_t>(w) * h * c)};
  for (float& v : img.pixels) v = u(rng);
  return img;
}

TEST(Metrics, PsnrByHand) {
  Image a{2, 1, 1, {0.0f, 0.5f}}, b{2, 1, 1, {0.1f, 0.5f}};
  EXPECT_NEAR(*Psnr(a, b), -10 * std::log10(0.01 / 2), 1e-5);
  EXPECT_TRUE(std::isinf(*Psnr(a, a)));
  EXPECT_FALSE(Psnr(a, Image{1, 1, 1, {0.0f}}).ok());
}

// Direct 11x11 windowed SSIM (zero padding), the reference for the separable implementation.
double BruteSsim(const Image& a, const Image& b) {
  double kernel[11][11], sum = 0;
  for (int i = 0; i < 11; ++i)
    for (int j = 0; j < 11; ++j)
      sum += kernel[i][j] = std::exp(-((i - 5) * (i - 5) + (j - 5) * (j - 5)) / (2 * 1.5 * 1.5));
  double total = 0;
  for (int c = 0; c < a.channels; ++c) {
    for (int y = 0; y < a.height; ++y) {
      for (int x = 0; x < a.width; ++x) {
        double mx = 0, my = 0, sxx = 0, syy = 0, sxy = 0;
        for (int i = -5; i <= 5; ++i) {
          for (int j = -5; j <= 5; ++j) {
            if (y + i < 0 || y + i >= a.height || x + j < 0 || x + j >= a.width) continue;
            const double k = kernel[i + 5][j + 5] / sum;
            const size_t p = (static_cast<size_t>(y + i) * a.width + x + j) * a.channels + c;
            mx += k * a.pixels[p];
            my += k * b.pixels[p];
            sxx += k * a.pixels[p] * a.pixels[p];
            syy += k * b.pixels[p] * b.pixels[p];
            sxy += k * a.pixels[p] * b.pixels[p];
          }
        }
        const double c1 = 1e-4, c2 = 9e-4;
        total += ((2 * mx * my + c1) * (2 * (sxy - mx * my) + c2)) /
                 ((mx * mx + my * my + c1) * (sxx - mx * mx + syy - my * my + c2));
      }
    }
  }
  return total / (static_cast<double>(a.width) * a.height * a.channels);
}

TEST(Metrics, SsimMatchesDirectWindowedSum) {
  for (uint32_t seed = 1; seed <= 4; ++seed) {
    const Image a = RandomImage(23, 17, 3, seed), b = RandomImage(23, 17, 3, seed + 10);
    EXPECT_NEAR(*Ssim(a, b), BruteSsim(a, b), 1e-9);
  }
  const Image a = RandomImage(20, 20, 1, 3);
  EXPECT_NEAR(*Ssim(a, a), 1.0, 1e-12);
}

TEST(GeometryMetrics, PointCloudsMatchBruteForce) {
  std::mt19937 rng(8);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<Eigen::Vector3f> p(300), q(250);
  for (auto& v : p) v = {u(rng), u(rng), u(rng)};
  for (auto& v : q) v = {u(rng), u(rng), 0.2f * u(rng)};
  const double tau = 0.08;
  auto one_way = [](const auto& from, const auto& to, double t, double* close) {
    double sum = 0;
    *close = 0;
    for (const auto& a : from) {
      double best = 1e30;
      for (const auto& b : to) best = std::min(best, static_cast<double>((a - b).norm()));
      sum += best;
      *close += best <= t;
    }
    *close /= from.size();
    return sum / from.size();
  };
  double prec = 0, rec = 0;
  const double chamfer = 0.5 * (one_way(p, q, tau, &prec) + one_way(q, p, tau, &rec));
  const PointCloudComparison c = ComparePointClouds(p, q, tau);
  EXPECT_NEAR(c.chamfer, chamfer, 1e-6);
  EXPECT_NEAR(c.precision, prec, 1e-12);
  EXPECT_NEAR(c.recall, rec, 1e-12);
  EXPECT_NEAR(c.f1, 2 * prec * rec / (prec + rec), 1e-12);
  EXPECT_DOUBLE_EQ(ComparePointClouds(p, p, 1e-6).f1, 1.0);
}

TEST(GeometryMetrics, VolumeIouOfShiftedCubesAndSphereVolume) {
  TriangleMesh a = MakeShapeMesh({ShapeKind::kBox, {1, 1, 1}});
  TriangleMesh b = a;
  b.Transform({Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.5, 0, 0)});
  EXPECT_NEAR(VolumeIou(a, b, 64), 1.0 / 3.0, 0.02);
  EXPECT_NEAR(VolumeIou(a, a, 64), 1.0, 1e-12);
  TriangleMesh far = a;
  far.Transform({Eigen::Matrix3d::Identity(), Eigen::Vector3d(3, 0, 0)});
  EXPECT_EQ(VolumeIou(a, far, 64), 0.0);
  const TriangleMesh sphere = MakeShapeMesh({ShapeKind::kSphere, {0.5f, 0, 0}}, 96);
  Eigen::AlignedBox3f box(Eigen::Vector3f(-0.5f, -0.5f, 0.0f), Eigen::Vector3f(0.5f, 0.5f, 1.0f));
  const std::vector<uint8_t> vox = VoxelizeClosedMesh(sphere, box, 64);
  const double filled = std::count(vox.begin(), vox.end(), 1) / std::pow(64.0, 3);
  EXPECT_NEAR(filled, 4.0 / 3.0 * std::numbers::pi * 0.125, 0.01);
}

class ClickProtocol : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    temp_ = new instascene::testing::ScopedTempDir("click_eval_scene");
    dir_ = new std::string(temp_->Sub("scene"));
    absl::StatusOr<ClutterScene> scene = GenerateClutterScene(*ClutterPreset("tiny"));
    ASSERT_TRUE(scene.ok());
    SceneWriteOptions options;
    options.mask_noise = "none";
    ASSERT_TRUE(WriteClutterScene(*scene, *dir_, options).ok());
    ids_ = new std::vector<uint32_t>(scene->instance_ids.begin(), scene->instance_ids.end());
    cloud_ = new GaussianCloud(scene->cloud);
  }
  static void TearDownTestSuite() {
    delete temp_;
    temp_ = nullptr;
  }
  static instascene::testing::ScopedTempDir* temp_;
  static std::string* dir_;
  static std::vector<uint32_t>* ids_;
  static GaussianCloud* cloud_;
};
instascene::testing::ScopedTempDir* ClickProtocol::temp_ = nullptr;
std::string* ClickProtocol::dir_ = nullptr;
std::vector<uint32_t>* ClickProtocol::ids_ = nullptr;
GaussianCloud* ClickProtocol::cloud_ = nullptr;

TEST_F(ClickProtocol, GroundTruthScoresOne) {
  SegmentationResult gt;
  gt.stage = "ground-truth";
  gt.labels = *ids_;
  const std::string result_dir = *dir_ + "_gt_result";
  ASSERT_TRUE(WriteResult(result_dir, gt, *cloud_).ok());
  absl::StatusOr<ClickEvaluation> eval =
      EvaluateResultDirectory(*dir_, result_dir, ClickEvalOptions{});
  ASSERT_TRUE(eval.ok()) << eval.status();
  EXPECT_FALSE(eval->used_features);
  EXPECT_EQ(eval->objects.size(), 5u);
  EXPECT_DOUBLE_EQ(eval->miou, 1.0);
  EXPECT_DOUBLE_EQ(eval->instances.recall, 1.0);
  EXPECT_DOUBLE_EQ(eval->instances.precision, 1.0);
  EXPECT_DOUBLE_EQ(eval->adjusted_rand_index, 1.0);
  // With one-hot features the protocol uses cosine masks: near-perfect, but boundary pixels that
  // mix two instances fall below cos 0.9.
  gt.feature_dim = 6;
  gt.features.assign(ids_->size() * 6, 0.0f);
  for (size_t i = 0; i < ids_->size(); ++i) gt.features[i * 6 + (*ids_)[i]] = 1.0f;
  ASSERT_TRUE(WriteResult(result_dir, gt, *cloud_).ok());
  eval = EvaluateResultDirectory(*dir_, result_dir, ClickEvalOptions{});
  ASSERT_TRUE(eval.ok()) << eval.status();
  EXPECT_TRUE(eval->used_features);
  EXPECT_GT(eval->miou, 0.9);
  EXPECT_LT(eval->miou, 1.0);
}

TEST_F(ClickProtocol, MergedObjectScoresWhatItShould) {
  // Objects 1 and 2 (two of the touching identical bottles) merged into one instance.
  SegmentationResult merged;
  merged.labels = *ids_;
  for (uint32_t& l : merged.labels) l = l == 2 ? 1 : l;
  absl::StatusOr<Scene> scene = ReadScene(*dir_);
  ASSERT_TRUE(scene.ok());
  std::vector<std::vector<uint32_t>> gt_masks, pred_maps;
  for (size_t v = 0; v < scene->views.size(); ++v) {
    LabelMap m = *ReadLabelMap(*dir_ + "/gt/masks/" + scene->views[v].name + ".png");
    gt_masks.emplace_back(m.labels.begin(), m.labels.end());
    pred_maps.push_back(*RenderLabelMap(*cloud_, scene->views[v].camera, merged.labels));
  }
  // Expected by hand: each object's reference view is its largest GT mask; objects 1 and 2 both
  // select label 1 there (the mode), so their masks are {pred == 1}; others select themselves.
  ClickEvalOptions options;
  double expected_total = 0;
  for (uint32_t id = 1; id <= 5; ++id) {
    int ref = -1;
    size_t ref_area = 0;
    double sum = 0;
    int views = 0;
    for (size_t v = 0; v < gt_masks.size(); ++v) {
      const size_t area = std::count(gt_masks[v].begin(), gt_masks[v].end(), id);
      if (area < static_cast<size_t>(options.min_visible_pixels)) continue;
      if (area > ref_area) {
        ref_area = area;
        ref = static_cast<int>(v);
      }
    }
    std::map<uint32_t, size_t> votes;
    for (size_t p = 0; p < gt_masks[ref].size(); ++p)
      if (gt_masks[ref][p] == id) ++votes[pred_maps[ref][p]];
    const uint32_t selected = std::max_element(votes.begin(), votes.end(), [](auto& a, auto& b) {
                                return a.second < b.second;
                              })->first;
    EXPECT_EQ(selected, id == 2 ? 1u : id);
    for (size_t v = 0; v < gt_masks.size(); ++v) {
      if (std::count(gt_masks[v].begin(), gt_masks[v].end(), id) < options.min_visible_pixels)
        continue;
      sum += MaskIou(pred_maps[v], selected, gt_masks[v], id);
      ++views;
    }
    expected_total += sum / views;
  }
  std::vector<std::string> names;
  absl::StatusOr<ClickEvaluation> eval =
      EvaluateClicks(*scene, *cloud_, gt_masks, *ids_, merged, names, options);
  ASSERT_TRUE(eval.ok()) << eval.status();
  EXPECT_NEAR(eval->miou, expected_total / 5.0, 1e-12);
  EXPECT_LT(eval->miou, 0.9);
  EXPECT_DOUBLE_EQ(eval->objects[2].miou, 1.0);  // untouched objects are still perfect
  // Over observed Gaussians the merged set overlaps the better-seen bottle by more than half: it
  // matches that one, never both.
  EXPECT_EQ(eval->instances.matched, 4);
  EXPECT_DOUBLE_EQ(eval->instances.recall, 0.8);
}

// result.json summarises each instance: its Gaussian count, the centroid and the box of their
// centres. The heap is first filled with freed map nodes holding NaN, where the writer once
// accumulated its centroids into default-constructed (uninitialised) Eigen vectors.
TEST(Result, InstancesSummariseTheirGaussians) {
  {
    std::map<uint32_t, Eigen::Vector3d> garbage;
    for (uint32_t k = 0; k < 4096; ++k) garbage[k].setConstant(std::nan(""));
  }
  const instascene::testing::ScopedTempDir temp("result_summary");
  const std::string dir = temp.Sub("result");
  constexpr uint32_t kInstances = 300;
  GaussianCloud cloud;
  cloud.Resize(3 * kInstances + 1);
  SegmentationResult r;
  r.labels.assign(cloud.size(), 0);  // the last Gaussian is background
  for (uint32_t k = 0; k < kInstances; ++k) {
    for (uint32_t j = 0; j < 3; ++j) {
      const uint32_t g = 3 * k + j;
      r.labels[g] = k + 1;
      cloud.positions[3 * g] = static_cast<float>(k);       // x: the instance
      cloud.positions[3 * g + 1] = static_cast<float>(j);   // y: 0, 1, 2
      cloud.positions[3 * g + 2] = -static_cast<float>(j);  // z: 0, -1, -2
    }
  }
  ASSERT_TRUE(WriteResult(dir, r, cloud).ok());
  const nlohmann::json j =
      nlohmann::json::parse(*ReadFileBounded(dir + "/result.json", size_t{64} << 20));
  ASSERT_EQ(j["instances"].size(), kInstances);
  for (uint32_t k = 0; k < kInstances; ++k) {
    const nlohmann::json& instance = j["instances"][k];
    ASSERT_EQ(instance["id"], k + 1);
    EXPECT_EQ(instance["gaussians"], 3);
    const std::vector<double> centroid = instance["centroid"];
    EXPECT_NEAR(centroid[0], k, 1e-9) << k;
    EXPECT_NEAR(centroid[1], 1.0, 1e-9) << k;
    EXPECT_NEAR(centroid[2], -1.0, 1e-9) << k;
    EXPECT_EQ(instance["bounds_min"], nlohmann::json({double(k), 0.0, -2.0}));
    EXPECT_EQ(instance["bounds_max"], nlohmann::json({double(k), 2.0, 0.0}));
  }
}

TEST(Result, RejectsWrongSizesAndMalformedFiles) {
  const instascene::testing::ScopedTempDir temp("bad_result");
  const std::string dir = temp.Sub("result");
  GaussianCloud cloud;
  cloud.Resize(4);
  SegmentationResult r;
  r.labels = {1, 0, 2};
  EXPECT_FALSE(WriteResult(dir, r, cloud).ok());
  r.labels = {1, 0, 2, 2};
  ASSERT_TRUE(WriteResult(dir, r, cloud).ok());
  EXPECT_TRUE(ReadResult(dir, 4).ok());
  EXPECT_FALSE(ReadResult(dir, 5).ok());
  ASSERT_TRUE(WriteFileAtomically(dir + "/result.json", "{\"format\": \"nope\"}").ok());
  EXPECT_FALSE(ReadResult(dir, 4).ok());
}

}  // namespace
}  // namespace instascene
