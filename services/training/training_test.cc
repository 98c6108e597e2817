#include <gtest/gtest.h>

#include "common/core/testing/temp_dir.h"

#include <filesystem>
#include <random>

#include "common/core/status.h"
#include "common/eval/click_eval.h"
#include "common/synth/scene_writer.h"
#include "services/decomposition/decompose.h"
#include "services/training/contrastive_loss.h"
#include "services/training/feature_field.h"
#include "services/training/segmentation.h"

namespace instascene::training {
namespace {

// Features in tight clusters around class directions: every temperature clips to 0.5, so the
// detached temperature has zero derivative and finite differences see exactly the analytic maths.
std::vector<float> ClusteredFeatures(const std::vector<uint32_t>& cls, int dim, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, 0.01f);
  std::vector<float> x(cls.size() * dim);
  for (size_t j = 0; j < cls.size(); ++j) {
    for (int d = 0; d < dim; ++d)
      x[j * dim + d] = (d == static_cast<int>(cls[j] % dim) ? 1.5f : 0.1f) + noise(rng);
  }
  return x;
}

TEST(ContrastiveLoss, GradientMatchesFiniteDifferences) {
  const int dim = 5;
  const std::vector<uint32_t> labels = {1, 1, 2, 2, 2, 3, 0, 3};
  for (bool negatives : {false, true}) {
    std::vector<float> x = ClusteredFeatures(labels, dim, 3);
    ContrastiveLossOptions options;
    options.consider_negative = negatives;
    options.detach_norm = false;
    std::vector<double> grad, unused;
    ContrastiveLoss(x, dim, labels, options, &grad);
    for (size_t i = 0; i < x.size(); ++i) {
      const float h = 1e-3f;
      std::vector<float> plus = x, minus = x;
      plus[i] += h;
      minus[i] -= h;
      const double fd = (ContrastiveLoss(plus, dim, labels, options, &unused) -
                         ContrastiveLoss(minus, dim, labels, options, &unused)) /
                        (plus[i] - minus[i]);
      EXPECT_NEAR(grad[i], fd, 2e-3 * std::max(1.0, std::abs(fd)))
          << i << " negatives " << negatives;
    }
  }
}

TEST(ContrastiveLoss, SeparatedClassesScoreLowerThanMixedOnes) {
  const std::vector<uint32_t> labels = {1, 1, 1, 2, 2, 2};
  std::vector<double> grad;
  const double separated = ContrastiveLoss(ClusteredFeatures(labels, 4, 1), 4, labels, {}, &grad);
  std::vector<float> mixed = ClusteredFeatures({1, 2, 1, 2, 1, 2}, 4, 1);
  const double confused = ContrastiveLoss(mixed, 4, labels, {}, &grad);
  EXPECT_LT(separated, confused);
  EXPECT_EQ(ContrastiveLoss(mixed, 4, {1, 1, 1, 1, 1, 1}, {}, &grad),
            0.0);  // one class: no contrast
}

// Hand-built training data: 2 views of 40 pool pixels, each rendered by 1-3 Gaussians of one class.
TrainingData HandData(int dim, std::vector<float>* features) {
  std::mt19937 rng(5);
  TrainingData data;
  data.num_gaussians = 30;
  data.labels3d.resize(30);
  std::vector<uint32_t> cls(30);
  for (uint32_t g = 0; g < 30; ++g) cls[g] = data.labels3d[g] = 1 + g % 3;
  *features = ClusteredFeatures(cls, dim, 9);
  for (int v = 0; v < 2; ++v) {
    ViewData view;
    view.offsets.push_back(0);
    for (int p = 0; p < 40; ++p) {
      const uint32_t c = 1 + rng() % 3;
      const int k = 1 + static_cast<int>(rng() % 3);
      for (int e = 0; e < k; ++e) {
        view.gaussians.push_back(c - 1 + 3 * static_cast<uint32_t>(rng() % 10));
        view.weights.push_back(0.2f + 0.25f * static_cast<float>(rng() % 3));
      }
      view.offsets.push_back(view.gaussians.size());
      view.raw_label.push_back(c);
      view.filtered_label.push_back(c);
      view.sorted_label.push_back(c);
    }
    for (uint32_t g = 0; g < 30; ++g) view.visible_labelled.push_back(g);
    data.views.push_back(view);
  }
  return data;
}

TEST(FeatureField, GradientOfAllTermsMatchesFiniteDifferences) {
  const int dim = 4;
  std::vector<float> features;
  const TrainingData data = HandData(dim, &features);
  TrainingOptions options;
  options.feature_dim = dim;
  options.samples = 64;
  options.consider_negative = false;
  options.detach_sample_norm = false;
  options.lambda_single = options.lambda_multi = options.lambda_3d =
      1.0;  // unit weights for the check
  std::vector<double> grad, unused;
  LossAndGradient(data, options, features, 1, true, 42, &grad);
  for (size_t i = 0; i < features.size(); i += 3) {
    const float h = 1e-3f;
    std::vector<float> plus = features, minus = features;
    plus[i] += h;
    minus[i] -= h;
    const double fd = (LossAndGradient(data, options, plus, 1, true, 42, &unused) -
                       LossAndGradient(data, options, minus, 1, true, 42, &unused)) /
                      (plus[i] - minus[i]);
    EXPECT_NEAR(grad[i], fd, 3e-3 * std::max(1.0, std::abs(fd))) << "feature entry " << i;
  }
}

TEST(Segmentation, AssignsByMeanFeatureWithThreshold) {
  // Two coarse instances and one unlabelled Gaussian whose feature matches instance 2.
  const std::vector<float> f = {1, 0, 1, 0.05f, 0, 1, 0.02f, 1, 0, 1, 0.7f, 0.7f};
  const std::vector<uint32_t> coarse = {1, 1, 2, 0, 2, 0};
  const std::vector<uint32_t> labels = SegmentByFeatures(f, 2, coarse, {}, SegmentOptions{});
  EXPECT_EQ(labels, (std::vector<uint32_t>{1, 1, 2, 2, 2, 0}));  // (0.7, 0.7) is below 0.9 for both
}

TEST(Segmentation, AnInstanceItsFeaturesCannotHoldKeepsItsCoarseMask) {
  // Instance 2's five Gaussians carry instance 1's feature but one: at tau 0.15 its features select
  // only that one (1 of 5 < 25 %), so it keeps its coarse mask; instance 1 is intact.
  const std::vector<float> f = {1, 0, 1, 0, 1, 0, 1, 0, 1, 0, 1, 0, 1, 0, 0, 1};
  const std::vector<uint32_t> coarse = {1, 1, 1, 2, 2, 2, 2, 2};
  SegmentOptions options;
  options.threshold = 0.15;
  EXPECT_EQ(SegmentByFeatures(f, 2, coarse, {}, options),
            (std::vector<uint32_t>{1, 1, 1, 2, 2, 2, 2, 2}));
  options.min_kept_share = 0.0;  // the plain tau rule: the sliver
  EXPECT_EQ(SegmentByFeatures(f, 2, coarse, {}, options),
            (std::vector<uint32_t>{1, 1, 1, 1, 1, 1, 1, 2}));
}

TEST(Segmentation, AnInstanceWhoseMeanDriftedToTheBackgroundKeepsItsCoarseMask) {
  // Instance 2 (two Gaussians) shares its feature with eight unlabelled background Gaussians and
  // with one of instance 1's twenty: its features select 11 > 3 x 2 Gaussians, so it keeps its
  // coarse mask and what it took returns to its coarse label (0 for the background, 1 for instance
  // 1's).
  std::vector<float> f;
  std::vector<uint32_t> coarse;
  auto add = [&](float x, float y, uint32_t label, int count) {
    for (int i = 0; i < count; ++i) {
      f.insert(f.end(), {x, y});
      coarse.push_back(label);
    }
  };
  add(1, 0, 1, 19);
  add(0, 1, 1, 1);
  add(0, 1, 2, 2);
  add(0.1f, 1, 0, 8);
  SegmentOptions options;
  EXPECT_EQ(SegmentByFeatures(f, 2, coarse, {}, options), coarse);
  options.max_growth = 0;  // the plain tau rule: instance 2 spreads over the background
  std::vector<uint32_t> expected(19, 1);
  expected.resize(coarse.size(), 2);
  EXPECT_EQ(SegmentByFeatures(f, 2, coarse, {}, options), expected);
}

TEST(Segmentation, AnUnclaimedGaussianItsNeighboursCarryKeepsItsInstance) {
  // Instance 1: twenty Gaussians on a line (x = 0..19) with feature (1, 0), then two whose feature
  // (0.8, 0.6) matches the instance's mean only 0.83 (below tau) at x = 20 and 21, a third such far
  // away among the background, one inside the line matching 0.57 and one such off the line's end,
  // 5 above it. Background (0, 1) at x = 22..40 and 95..105. The one at x = 20 has four of its
  // eight nearest in the instance, the one at 21 three, then four once 20 is kept; the far one
  // none. The inner one matches too little for half its neighbours to keep it, but all eight carry
  // the instance (surrounded by its object: kept); the one off the end has five of eight.
  std::vector<float> f, positions;
  std::vector<uint32_t> coarse;
  auto add = [&](float x, float y, float fx, float fy, uint32_t label) {
    f.insert(f.end(), {fx, fy});
    positions.insert(positions.end(), {x, y, 0});
    coarse.push_back(label);
  };
  for (int x = 0; x < 20; ++x) add(x, 0, 1, 0, 1);
  add(20, 0, 0.8f, 0.6f, 1);
  add(21, 0, 0.8f, 0.6f, 1);
  add(100, 0.5f, 0.8f, 0.6f, 1);
  add(10, 0.5f, 0.5f, 0.866f, 1);
  add(20.5f, 5, 0.5f, 0.866f, 1);
  for (int x = 22; x <= 40; ++x) add(x, 0, 0, 1, 0);
  for (int x = 95; x <= 105; ++x) add(x, 0, 0, 1, 0);
  std::vector<uint32_t> expected(coarse.size(), 0);
  for (int g = 0; g < 22; ++g) expected[g] = 1;
  expected[23] = 1;  // surrounded
  EXPECT_EQ(SegmentByFeatures(f, 2, coarse, positions, SegmentOptions{}), expected);
  SegmentOptions half_only;
  half_only.keep_surrounded = 2;  // off: the inner one falls to the background
  expected[23] = 0;
  EXPECT_EQ(SegmentByFeatures(f, 2, coarse, positions, half_only), expected);
  SegmentOptions paper;
  paper.keep_neighbours = 0;  // the paper's rule: all five fall to the background
  expected[20] = expected[21] = 0;
  EXPECT_EQ(SegmentByFeatures(f, 2, coarse, positions, paper), expected);
  EXPECT_EQ(SegmentByFeatures(f, 2, coarse, {}, SegmentOptions{}), expected);  // no centres
}

// The small preset written into `dir` with `noise` masks and decomposed into dir/decomposition.
struct DecomposedScene {
  Scene scene;
  GaussianCloud cloud;
};
absl::StatusOr<DecomposedScene> WriteDecomposedScene(const std::string& dir,
                                                     const std::string& noise) {
  ASSIGN_OR_RETURN(ClutterScene clutter, GenerateClutterScene(*ClutterPreset("small")));
  SceneWriteOptions write;
  write.mask_noise = noise;
  RETURN_IF_ERROR(WriteClutterScene(clutter, dir, write));
  ASSIGN_OR_RETURN(Scene scene, ReadScene(dir));
  ASSIGN_OR_RETURN(decomposition::DecompositionResult coarse,
                   decomposition::Decompose(scene, clutter.cloud, {}));
  RETURN_IF_ERROR(
      decomposition::WriteDecomposition(dir + "/decomposition", scene, clutter.cloud, coarse));
  return DecomposedScene{std::move(scene), std::move(clutter.cloud)};
}

// A removed (under-segmented) mask's pixels take no part in the single-view term: the Gaussians
// that render only such pixels get no gradient from it, where as background pixels they would.
TEST(FeatureField, RemovedMasksPixelsAreLeftOutOfTheSingleViewTerm) {
  const int dim = 4;
  std::vector<float> features;
  TrainingData data = HandData(dim, &features);
  TrainingOptions options;
  options.feature_dim = dim;
  options.samples = 256;
  options.supervision = Supervision::k3dFiltered2d;
  for (ViewData& view : data.views) view.visible_labelled.clear();  // no 3D term
  auto class2_gradient = [&](uint32_t removed_label) {
    TrainingData d = data;
    for (ViewData& view : d.views) {
      for (uint32_t& label : view.filtered_label) {
        if (label == 2) label = removed_label;
      }
    }
    std::vector<double> grad;
    LossAndGradient(d, options, features, 0, false, 7, &grad);
    double norm = 0;
    for (uint32_t g = 1; g < 30; g += 3) {  // class 2's Gaussians render only class 2's pixels
      for (int k = 0; k < dim; ++k) norm += std::abs(grad[g * dim + k]);
    }
    return norm;
  };
  EXPECT_GT(class2_gradient(0), 0.0);  // as background (the released code)
  EXPECT_EQ(class2_gradient(kIgnoredLabel), 0.0);
}

// The decomposition's removed masks reach the training as background by default (the released
// code) and as ignored pixels with ignore_removed_masks; read on a high-noise scene with merges.
TEST(FeatureField, PreparedLabelsMarkTheRemovedMasksPixels) {
  const instascene::testing::ScopedTempDir temp("removed_masks");
  const std::string dir = temp.Sub("scene");
  absl::StatusOr<DecomposedScene> scene = WriteDecomposedScene(dir, "high");
  ASSERT_TRUE(scene.ok()) << scene.status();
  const std::string decomposition = dir + "/decomposition";
  TrainingOptions left_out, background;
  left_out.pixel_pool = background.pixel_pool = 4096;
  left_out.ignore_removed_masks = true;
  absl::StatusOr<TrainingData> a =
      PrepareTraining(scene->scene, scene->cloud, decomposition, left_out);
  absl::StatusOr<TrainingData> b =
      PrepareTraining(scene->scene, scene->cloud, decomposition, background);
  ASSERT_TRUE(a.ok() && b.ok());
  int removed = 0;
  for (size_t v = 0; v < a->views.size(); ++v) {
    const ViewData& x = a->views[v];
    const ViewData& y = b->views[v];
    ASSERT_EQ(x.raw_label, y.raw_label);  // the same pool pixels
    for (size_t p = 0; p < x.raw_label.size(); ++p) {
      if (x.raw_label[p] > 0 && y.filtered_label[p] == 0) {
        EXPECT_EQ(x.filtered_label[p], kIgnoredLabel);
        ++removed;
      } else {
        EXPECT_EQ(x.filtered_label[p], y.filtered_label[p]);
      }
    }
  }
  EXPECT_GT(removed, 0);  // high noise merges touching objects in some views
}

TEST(FeatureField, TrainingOnASyntheticSceneSeparatesInstances) {
  const instascene::testing::ScopedTempDir temp("training_scene");
  const std::string dir = temp.Sub("scene");
  absl::StatusOr<DecomposedScene> scene = WriteDecomposedScene(dir, "medium");
  ASSERT_TRUE(scene.ok()) << scene.status();
  TrainingOptions options;
  options.iterations = 300;
  options.samples = 2048;
  options.pixel_pool = 4096;
  absl::StatusOr<TrainingData> data =
      PrepareTraining(scene->scene, scene->cloud, dir + "/decomposition", options);
  ASSERT_TRUE(data.ok()) << data.status();
  absl::StatusOr<TrainingResult> trained = TrainFeatures(*data, options);
  ASSERT_TRUE(trained.ok()) << trained.status();
  double first = 0, last = 0;
  for (int i = 0; i < 20; ++i) {
    first += trained->loss[i];
    last += trained->loss[trained->loss.size() - 1 - i];
  }
  EXPECT_LT(last, 0.5 * first);  // the loss falls
  const SegmentationResult result =
      TrainedResult(*trained, *data, scene->cloud, options.feature_dim, SegmentOptions{});
  EXPECT_EQ(result.feature_dim, options.feature_dim);
  ASSERT_TRUE(WriteResult(dir + "/trained", result, scene->cloud).ok());
  absl::StatusOr<ClickEvaluation> features =
      EvaluateResultDirectory(dir, dir + "/trained", ClickEvalOptions{});
  absl::StatusOr<ClickEvaluation> labels =
      EvaluateResultDirectory(dir, dir + "/decomposition", ClickEvalOptions{});
  ASSERT_TRUE(features.ok() && labels.ok());
  EXPECT_GT(features->miou, 0.6) << "feature click mIoU; decomposition labels give "
                                 << labels->miou;
}

}  // namespace
}  // namespace instascene::training
