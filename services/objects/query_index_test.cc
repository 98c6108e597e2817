#include "services/objects/query_index.h"

#include <gtest/gtest.h>

#include "common/core/testing/temp_dir.h"
#include "common/scene/image_io.h"
#include "common/synth/scene_writer.h"

namespace instascene::objects {
namespace {

TEST(Query, ClicksAndPointsReturnTheGroundTruthInstance) {
  const instascene::testing::ScopedTempDir temp("query_scene");
  const std::string dir = temp.Sub("scene");
  absl::StatusOr<ClutterScene> scene = GenerateClutterScene(*ClutterPreset("tiny"));
  ASSERT_TRUE(scene.ok());
  ASSERT_TRUE(WriteClutterScene(*scene, dir, SceneWriteOptions{}).ok());
  absl::StatusOr<Scene> read = ReadScene(dir);
  ASSERT_TRUE(read.ok());
  absl::StatusOr<SegmentationResult> gt = ReadResult(dir + "/gt", scene->cloud.size());
  ASSERT_TRUE(gt.ok());
  absl::StatusOr<std::unique_ptr<QueryIndex>> index = QueryIndex::Build(*read, scene->cloud, *gt);
  ASSERT_TRUE(index.ok()) << index.status();
  const int view = 4;
  absl::StatusOr<LabelMap> mask =
      ReadLabelMap(dir + "/gt/masks/" + read->views[view].name + ".png");
  ASSERT_TRUE(mask.ok());
  int clicked = 0;
  for (size_t p = 0; p < mask->labels.size(); p += 37) {
    const int x = static_cast<int>(p % mask->width), y = static_cast<int>(p / mask->width);
    absl::StatusOr<QueryAnswer> answer = (*index)->Click(view, x, y);
    ASSERT_TRUE(answer.ok());
    ASSERT_EQ(answer->instance, mask->labels[p]);
    if (answer->instance == 0) continue;
    ++clicked;
    EXPECT_EQ(answer->gaussians, scene->objects[answer->instance - 1].num_gaussians);
    const std::vector<uint8_t> m = (*index)->Mask(answer->instance, view);
    for (size_t q = 0; q < m.size(); ++q) ASSERT_EQ(m[q] != 0, mask->labels[q] == answer->instance);
  }
  EXPECT_GT(clicked, 10);
  const SynthObject& o = scene->objects[2];
  absl::StatusOr<QueryAnswer> at =
      (*index)->Point(Eigen::Vector3f(&scene->cloud.positions[3 * o.first_gaussian]), 0.01f);
  ASSERT_TRUE(at.ok());
  EXPECT_EQ(at->instance, static_cast<uint32_t>(o.id));
  EXPECT_EQ((*index)->Point(Eigen::Vector3f(50, 50, 50), 0.01f)->instance, 0u);
  // A ray through a clicked pixel's centre meets the same instance as the click, except at a few
  // object boundaries: a ray is thinner than a pixel's footprint (the low-pass filter differs).
  int agree = 0, rays = 0;
  for (size_t p = 0; p < mask->labels.size(); p += 53) {
    const int x = static_cast<int>(p % mask->width), y = static_cast<int>(p / mask->width);
    const PinholeCamera& cam = read->views[view].camera;
    const Eigen::Vector3f origin = cam.CenterInWorld().cast<float>();
    absl::StatusOr<QueryAnswer> ray =
        (*index)->Ray(origin, cam.PixelRayInWorld(x, y).cast<float>());
    ASSERT_TRUE(ray.ok());
    agree += ray->instance == mask->labels[p];
    ++rays;
  }
  EXPECT_GE(agree, rays * 95 / 100) << agree << " of " << rays;
  EXPECT_FALSE((*index)->Ray(Eigen::Vector3f::Zero(), Eigen::Vector3f::Zero()).ok());
  EXPECT_FALSE((*index)->Click(view, -1, 0).ok());
  EXPECT_FALSE((*index)->Click(99, 0, 0).ok());
}

}  // namespace
}  // namespace instascene::objects
