#include <gtest/gtest.h>

#include "common/synth/cluttered_scene.h"
#include "services/generation/completion.h"

namespace instascene::generation {
namespace {

TEST(Completion, Smoke) {
  auto preset = ClutterPreset("small");
  ASSERT_TRUE(preset.ok());
  auto scene = GenerateClutterScene(*preset);
  ASSERT_TRUE(scene.ok());
  std::vector<uint32_t> labels(scene->instance_ids.begin(), scene->instance_ids.end());
  for (const SynthObject& o : scene->objects) {
    auto done = CompleteObject(scene->cameras, scene->cloud, labels, o.id, CompletionOptions{});
    ASSERT_TRUE(done.ok()) << done.status();
    std::cout << o.name << " " << done->manifest.dump().substr(0, 1500) << "\n";
  }
}

}  // namespace
}  // namespace instascene::generation
