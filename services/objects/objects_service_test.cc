// The Objects service over a store holding a synthetic scene and its ground-truth segmentation:
// every selector against the ground truth, NOT_FOUND for what is not there, pagination, and the
// cache (one load shared by concurrent first queries, a byte budget).
#include "services/objects/objects_service.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <thread>

#include "common/core/testing/temp_dir.h"
#include "common/eval/result.h"
#include "common/metrics/metrics.h"
#include "common/rpc/status.h"
#include "common/scene/image_io.h"
#include "common/store/manifest.h"
#include "common/synth/scene_writer.h"

namespace instascene::objects {
namespace {

// A sample's value in the process's /metrics text (0 when absent).
double Metric(const std::string& sample) {
  const std::string text = metrics::SerializeText();
  const size_t at = text.find("\n" + sample + " ");
  return at == std::string::npos ? 0.0 : std::stod(text.substr(at + sample.size() + 2));
}

class ObjectsServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto store = store::FilesystemBlobStore::Open(temp_.Sub("store"), store::StoreOptions{});
    ASSERT_TRUE(store.ok());
    store_ = std::move(*store);
    for (uint32_t seed : {1u, 2u}) ASSERT_NO_FATAL_FAILURE(AddScene(seed));
  }

  // A scene "sN" with its ground truth uploaded as the segment output.
  void AddScene(uint32_t seed) {
    ClutterOptions preset = *ClutterPreset("tiny");
    preset.seed = seed;
    absl::StatusOr<ClutterScene> scene = GenerateClutterScene(preset);
    ASSERT_TRUE(scene.ok());
    const std::string dir = temp_.Sub("scene" + std::to_string(seed));
    ASSERT_TRUE(WriteClutterScene(*scene, dir, SceneWriteOptions{}).ok());
    absl::StatusOr<store::Manifest> scene_manifest = store::SceneManifestFromDirectory(dir);
    ASSERT_TRUE(scene_manifest.ok());
    absl::StatusOr<store::UploadReport> up = store::UploadManifest(*store_, *scene_manifest, dir);
    ASSERT_TRUE(up.ok()) << up.status();
    absl::StatusOr<SegmentationResult> gt = ReadResult(dir + "/gt", scene->cloud.size());
    ASSERT_TRUE(gt.ok());
    gt->stage = "segment";
    const std::string result_dir = temp_.Sub("segment" + std::to_string(seed));
    ASSERT_TRUE(WriteResult(result_dir, *gt, scene->cloud).ok());
    absl::StatusOr<store::Manifest> segment = store::ManifestFromDirectory(result_dir, "segment");
    ASSERT_TRUE(segment.ok());
    absl::StatusOr<store::UploadReport> seg_up =
        store::UploadManifest(*store_, *segment, result_dir);
    ASSERT_TRUE(seg_up.ok());
    v1::Scene described;
    described.set_name("s" + std::to_string(seed));
    v1::StageOutput* o = described.add_outputs();
    o->set_kind("segment");
    o->set_item(-1);
    rpc::ToProto(seg_up->manifest, o->mutable_output_manifest());
    rpc::ToProto(up->manifest, o->mutable_scene_manifest());
    scenes_[described.name()] = described;
    truth_[described.name()] = std::move(*scene);
    dirs_[described.name()] = dir;
  }

  std::unique_ptr<ObjectsService> Service(ObjectsServiceOptions options = {}) {
    return std::make_unique<ObjectsService>(
        store_.get(),
        [this](const std::string& name) -> absl::StatusOr<v1::Scene> {
          ++lookups_;
          auto it = scenes_.find(name);
          if (it == scenes_.end()) return absl::NotFoundError("scene '" + name + "' not found");
          return it->second;
        },
        options);
  }

  grpc::Status Get(ObjectsService& service, const std::string& scene,
                   const v1::ObjectSelector& selector, v1::Object* out) {
    v1::GetObjectRequest request;
    request.set_scene(scene);
    *request.mutable_selector() = selector;
    return service.GetObject(nullptr, &request, out);
  }

  instascene::testing::ScopedTempDir temp_{"objects_service"};
  std::unique_ptr<store::FilesystemBlobStore> store_;
  std::map<std::string, v1::Scene> scenes_;
  std::map<std::string, ClutterScene> truth_;
  std::map<std::string, std::string> dirs_;
  std::atomic<int> lookups_{0};
};

TEST_F(ObjectsServiceTest, EverySelectorFindsTheGroundTruthObject) {
  auto service = Service();
  const ClutterScene& truth = truth_["s1"];
  absl::StatusOr<Scene> scene = ReadScene(dirs_["s1"]);
  ASSERT_TRUE(scene.ok());
  const int view = 3;
  absl::StatusOr<LabelMap> mask =
      ReadLabelMap(dirs_["s1"] + "/gt/masks/" + scene->views[view].name + ".png");
  ASSERT_TRUE(mask.ok());
  int objects = 0, background = 0;
  for (size_t p = 0; p < mask->labels.size(); p += 41) {
    v1::ObjectSelector click;
    click.mutable_click()->set_view(scene->views[view].name);
    click.mutable_click()->set_x(static_cast<int>(p % mask->width));
    click.mutable_click()->set_y(static_cast<int>(p / mask->width));
    v1::Object o;
    const grpc::Status status = Get(*service, "s1", click, &o);
    if (mask->labels[p] == 0) {
      ASSERT_EQ(status.error_code(), grpc::StatusCode::NOT_FOUND);
      EXPECT_NE(status.error_message().find("background"), std::string::npos);
      ++background;
    } else {
      ASSERT_TRUE(status.ok()) << status.error_message();
      ASSERT_EQ(o.id(), mask->labels[p]);
      ++objects;
    }
  }
  EXPECT_GT(objects, 10);
  EXPECT_GT(background, 10);

  // By id: a raw crop in metres (the synthetic scene is metric), its extent the object's size.
  for (const SynthObject& so : truth.objects) {
    v1::ObjectSelector by_id;
    by_id.set_id(static_cast<uint32_t>(so.id));
    v1::Object o;
    ASSERT_TRUE(Get(*service, "s1", by_id, &o).ok());
    EXPECT_EQ(o.source(), "segment");
    EXPECT_EQ(o.units(), "metres");
    EXPECT_EQ(o.meters_per_unit(), 1.0);
    EXPECT_EQ(o.gaussians(), static_cast<int64_t>(so.num_gaussians));
    EXPECT_GT(o.extent().x() * o.extent().y() * o.extent().z(), 0);
    EXPECT_TRUE(o.index_loaded());
    ASSERT_EQ(o.artefacts_size(), 0);  // ground truth carries no per-instance splats

    // By a point on it (one of its Gaussians), and by a ray from a camera through that point.
    const Eigen::Vector3f at(
        &truth.cloud.positions[3 * (so.first_gaussian + so.num_gaussians / 2)]);
    v1::ObjectSelector point;
    point.mutable_point()->set_x(at.x());
    point.mutable_point()->set_y(at.y());
    point.mutable_point()->set_z(at.z());
    point.set_max_distance(0.005);
    ASSERT_TRUE(Get(*service, "s1", point, &o).ok());
    EXPECT_EQ(o.id(), static_cast<uint32_t>(so.id));
    // Just under its lowest Gaussian, in the table: the table's Gaussians are nearer, yet the
    // nearest *object* is this one.
    size_t lowest = so.first_gaussian;
    for (size_t g = so.first_gaussian; g < so.first_gaussian + so.num_gaussians; ++g)
      if (truth.cloud.positions[3 * g + 2] < truth.cloud.positions[3 * lowest + 2]) lowest = g;
    point.mutable_point()->set_x(truth.cloud.positions[3 * lowest]);
    point.mutable_point()->set_y(truth.cloud.positions[3 * lowest + 1]);
    point.mutable_point()->set_z(truth.cloud.positions[3 * lowest + 2] - 0.004);
    ASSERT_TRUE(Get(*service, "s1", point, &o).ok());
    EXPECT_EQ(o.id(), static_cast<uint32_t>(so.id));
  }
  // By a ray: from the camera through object pixels of the view (a ray is thinner than a pixel's
  // footprint and the masks are drawn from the meshes, so boundary pixels of this small image may
  // differ).
  const PinholeCamera& camera = scene->views[view].camera;
  int rays = 0, agree = 0;
  for (size_t p = 0; p < mask->labels.size(); p += 7) {
    if (mask->labels[p] == 0) continue;
    const Eigen::Vector3d origin = camera.CenterInWorld();
    const Eigen::Vector3d direction = camera.PixelRayInWorld(p % mask->width, p / mask->width);
    v1::ObjectSelector ray;
    ray.mutable_ray()->mutable_origin()->set_x(origin.x());
    ray.mutable_ray()->mutable_origin()->set_y(origin.y());
    ray.mutable_ray()->mutable_origin()->set_z(origin.z());
    ray.mutable_ray()->mutable_direction()->set_x(direction.x());
    ray.mutable_ray()->mutable_direction()->set_y(direction.y());
    ray.mutable_ray()->mutable_direction()->set_z(direction.z());
    v1::Object hit;
    agree += Get(*service, "s1", ray, &hit).ok() && hit.id() == mask->labels[p];
    ++rays;
  }
  EXPECT_GE(rays, 10);
  EXPECT_GE(agree, rays * 3 / 4) << agree << " of " << rays;
}

TEST_F(ObjectsServiceTest, WhatIsNotThereIsNotFoundAndMalformedSelectorsAreRefused) {
  auto service = Service();
  v1::Object o;
  v1::ObjectSelector id;
  id.set_id(999);
  grpc::Status s = Get(*service, "s1", id, &o);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(s.error_message().find("no object 999"), std::string::npos) << s.error_message();
  s = Get(*service, "nope", id, &o);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(s.error_message().find("nope"), std::string::npos);
  v1::ObjectSelector far;
  far.mutable_point()->set_x(50);
  s = Get(*service, "s1", far, &o);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_NE(s.error_message().find("no object within"), std::string::npos);
  v1::ObjectSelector up;  // straight up from above the table: nothing
  up.mutable_ray()->mutable_origin()->set_z(5);
  up.mutable_ray()->mutable_direction()->set_z(1);
  EXPECT_EQ(Get(*service, "s1", up, &o).error_code(), grpc::StatusCode::NOT_FOUND);

  EXPECT_EQ(Get(*service, "s1", v1::ObjectSelector(), &o).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(Get(*service, "", id, &o).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(Get(*service, std::string(300, 'x'), id, &o).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  v1::ObjectSelector bad_radius = far;
  bad_radius.set_max_distance(-1);
  EXPECT_EQ(Get(*service, "s1", bad_radius, &o).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  bad_radius.set_max_distance(1e9);
  EXPECT_EQ(Get(*service, "s1", bad_radius, &o).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  v1::ObjectSelector nan;
  nan.mutable_point()->set_x(std::nan(""));
  EXPECT_EQ(Get(*service, "s1", nan, &o).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  v1::ObjectSelector zero_ray;
  zero_ray.mutable_ray();
  EXPECT_EQ(Get(*service, "s1", zero_ray, &o).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  v1::ObjectSelector outside;
  outside.mutable_click()->set_view("0");
  outside.mutable_click()->set_x(100000);
  EXPECT_EQ(Get(*service, "s1", outside, &o).error_code(), grpc::StatusCode::OUT_OF_RANGE);
  outside.mutable_click()->set_view("no-such-view");
  EXPECT_NE(Get(*service, "s1", outside, &o).error_code(), grpc::StatusCode::OK);

  // A scene without a segmentation yet.
  v1::Scene fresh;
  fresh.set_name("fresh");
  scenes_["fresh"] = fresh;
  EXPECT_EQ(Get(*service, "fresh", id, &o).error_code(), grpc::StatusCode::FAILED_PRECONDITION);
}

TEST_F(ObjectsServiceTest, AMalformedStoredExportIsDataLossNotACrash) {
  // An export output whose object manifest has a quaternion of strings (a forged or corrupt
  // result).
  const std::string dir = temp_.Sub("bad-export");
  std::filesystem::create_directories(dir + "/1");
  std::ofstream(dir + "/objects.json") << R"({"objects": [{"id": 1, "dir": "1"}]})";
  std::ofstream(dir + "/1/manifest.json")
      << R"({"world_from_object": {"translation": [0, 0, 0], "quaternion_xyzw": ["a", "b", "c", "d"]},
            "bounding_box": {"extent": [1, 1, 1]}})";
  absl::StatusOr<store::Manifest> exported = store::ManifestFromDirectory(dir, "export");
  ASSERT_TRUE(exported.ok());
  absl::StatusOr<store::UploadReport> up = store::UploadManifest(*store_, *exported, dir);
  ASSERT_TRUE(up.ok());
  v1::Scene broken = scenes_["s1"];
  broken.set_name("broken");
  v1::StageOutput* o = broken.add_outputs();
  o->set_kind("export");
  o->set_item(-1);
  rpc::ToProto(up->manifest, o->mutable_output_manifest());
  *o->mutable_scene_manifest() = broken.outputs(0).scene_manifest();
  scenes_["broken"] = broken;
  auto service = Service();
  v1::ObjectSelector id;
  id.set_id(1);
  v1::Object answer;
  const grpc::Status status = Get(*service, "broken", id, &answer);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::DATA_LOSS) << status.error_message();
  EXPECT_NE(status.error_message().find("malformed"), std::string::npos);
  EXPECT_EQ(service->cache_stats().entries, 0);        // not cached: the next query tries again
  EXPECT_TRUE(Get(*service, "s1", id, &answer).ok());  // the service goes on
}

TEST_F(ObjectsServiceTest, ADamagedStoredBlobIsDataLossAndNothingIsWrittenToDisk) {
  auto listing = [&] {
    std::vector<std::string> paths;
    for (const auto& e : std::filesystem::recursive_directory_iterator(temp_.path()))
      paths.push_back(e.path().string());
    std::sort(paths.begin(), paths.end());
    return paths;
  };
  const std::vector<std::string> before = listing();
  const double failed_before = Metric(R"(instascene_objects_index_loads_total{outcome="failed"})");
  // Scene s2's labels damaged in the store: one byte of the last label flipped on disk.
  absl::StatusOr<store::Manifest> segment =
      store::ReadManifest(*store_, rpc::FromProto(scenes_["s2"].outputs(0).output_manifest()));
  ASSERT_TRUE(segment.ok()) << segment.status();
  const std::string blob = store_->BlobPath(segment->files.at("labels.ply"));
  std::filesystem::permissions(blob, std::filesystem::perms::owner_write,
                               std::filesystem::perm_options::add);
  {
    std::fstream file(blob, std::ios::in | std::ios::out | std::ios::binary);
    file.seekg(-1, std::ios::end);
    const char last = static_cast<char>(file.get());
    file.seekp(-1, std::ios::end);
    file.put(static_cast<char>(last ^ 0x01));
  }
  auto service = Service();
  v1::ObjectSelector id;
  id.set_id(1);
  v1::Object answer;
  const grpc::Status status = Get(*service, "s2", id, &answer);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::DATA_LOSS) << status.error_message();
  EXPECT_NE(status.error_message().find("labels.ply"), std::string::npos) << status.error_message();
  EXPECT_EQ(service->cache_stats().entries, 0);
  EXPECT_EQ(Metric(R"(instascene_objects_index_loads_total{outcome="failed"})") - failed_before, 1);
  ASSERT_TRUE(Get(*service, "s1", id, &answer).ok());  // the undamaged scene is answered
  EXPECT_EQ(answer.id(), 1u);
  EXPECT_EQ(listing(), before);  // indexes live in memory only
}

TEST_F(ObjectsServiceTest, ListObjectsPaginatesInIdOrder) {
  auto service = Service();
  std::vector<uint32_t> ids;
  std::string token;
  do {
    v1::ListObjectsRequest request;
    request.set_scene("s2");
    request.set_limit(2);
    request.set_page_token(token);
    v1::ListObjectsResponse page;
    ASSERT_TRUE(service->ListObjects(nullptr, &request, &page).ok());
    ASSERT_LE(page.objects_size(), 2);
    for (const v1::Object& o : page.objects()) ids.push_back(o.id());
    token = page.next_page_token();
  } while (!token.empty());
  std::vector<uint32_t> expected;
  for (const SynthObject& so : truth_["s2"].objects) expected.push_back(so.id);
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(ids, expected);
  v1::ListObjectsRequest bad;
  bad.set_scene("s2");
  bad.set_limit(5000);
  v1::ListObjectsResponse ignored;
  EXPECT_EQ(service->ListObjects(nullptr, &bad, &ignored).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  bad.set_limit(1);
  bad.set_page_token("x");
  EXPECT_EQ(service->ListObjects(nullptr, &bad, &ignored).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(ObjectsServiceTest, ConcurrentFirstQueriesShareOneLoadAndTheCacheKeepsItsBudget) {
  auto service = Service();
  const double loads_before = Metric(R"(instascene_objects_index_loads_total{outcome="ok"})");
  const double hits_before = Metric("instascene_objects_index_hits_total");
  std::vector<std::thread> threads;
  std::atomic<int> ok{0};
  for (int t = 0; t < 6; ++t) {
    threads.emplace_back([&] {
      v1::ObjectSelector id;
      id.set_id(1);
      v1::Object o;
      ok += Get(*service, "s1", id, &o).ok();
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(ok, 6);
  EXPECT_EQ(service->cache_stats().loads, 1);
  EXPECT_EQ(service->cache_stats().hits, 5);
  EXPECT_GT(service->cache_stats().bytes, 0);
  // What operators see (objects_metrics.h).
  EXPECT_EQ(Metric(R"(instascene_objects_index_loads_total{outcome="ok"})") - loads_before, 1);
  EXPECT_EQ(Metric("instascene_objects_index_hits_total") - hits_before, 5);
  EXPECT_EQ(Metric("instascene_objects_index_cache_entries"), 1);
  EXPECT_EQ(Metric("instascene_objects_index_cache_bytes"), service->cache_stats().bytes);

  // A budget smaller than one index keeps only the newest.
  ObjectsServiceOptions small;
  small.cache_bytes = 1;
  auto tight = Service(small);
  v1::ObjectSelector id;
  id.set_id(1);
  v1::Object o;
  ASSERT_TRUE(Get(*tight, "s1", id, &o).ok());
  ASSERT_TRUE(Get(*tight, "s2", id, &o).ok());
  EXPECT_EQ(tight->cache_stats().entries, 1);
  ASSERT_TRUE(Get(*tight, "s1", id, &o).ok());
  EXPECT_FALSE(o.index_loaded());  // evicted, loaded again
  EXPECT_EQ(tight->cache_stats().loads, 3);
}

TEST_F(ObjectsServiceTest, ARerunOrDeletedScenesIndexLeavesTheCacheAtOnce) {
  auto service = Service();
  v1::ObjectSelector id;
  id.set_id(1);
  v1::Object o;
  ASSERT_TRUE(Get(*service, "s1", id, &o).ok());
  ASSERT_TRUE(Get(*service, "s2", id, &o).ok());
  EXPECT_EQ(service->cache_stats().entries, 2);
  // s1 rerun: it now has other outputs (s2's); its old index goes, the budget notwithstanding.
  v1::Scene rerun = scenes_["s2"];
  rerun.set_name("s1");
  scenes_["s1"] = rerun;
  ASSERT_TRUE(Get(*service, "s1", id, &o).ok());
  EXPECT_FALSE(o.index_loaded());
  EXPECT_EQ(service->cache_stats().entries, 2);
  EXPECT_EQ(Metric("instascene_objects_index_cache_entries"), 2);
  ASSERT_TRUE(Get(*service, "s1", id, &o).ok());
  EXPECT_TRUE(o.index_loaded());
  // s2 deleted: its index goes, s1's stays; a failed lookup of another kind keeps s1's.
  scenes_.erase("s2");
  EXPECT_EQ(Get(*service, "s2", id, &o).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(service->cache_stats().entries, 1);
  scenes_["s1"].clear_outputs();  // before segmentation: FAILED_PRECONDITION
  EXPECT_EQ(Get(*service, "s1", id, &o).error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(service->cache_stats().entries, 1);
  scenes_.erase("s1");
  EXPECT_EQ(Get(*service, "s1", id, &o).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(service->cache_stats().entries, 0);
  EXPECT_EQ(service->cache_stats().bytes, 0);
  EXPECT_EQ(Metric("instascene_objects_index_cache_entries"), 0);
  EXPECT_EQ(service->cache_stats().loads, 3);
}

}  // namespace
}  // namespace instascene::objects
