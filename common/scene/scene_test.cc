#include <gtest/gtest.h>

#include "common/core/testing/temp_dir.h"

#include <OpenImageIO/imageio.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "common/core/file_io.h"
#include "common/scene/image_io.h"
#include "common/scene/importers.h"
#include "common/scene/scene.h"
#include "common/splat/ply.h"

namespace instascene {
namespace {

namespace fs = std::filesystem;

// A fresh directory that lives until the test process exits (each test case is its own process).
std::string FreshDir(const std::string& name) {
  static std::vector<std::unique_ptr<instascene::testing::ScopedTempDir>> dirs;
  dirs.push_back(std::make_unique<instascene::testing::ScopedTempDir>("scene_test_" + name));
  return dirs.back()->str();
}

SceneView MakeView(const std::string& name, double yaw) {
  SceneView v;
  v.name = name;
  v.image = "images/" + name + ".png";
  v.mask = "masks/" + name + ".png";
  v.camera = OrbitCamera({0, 0, 0}, {0, 0, 1}, 3.0, yaw, 20.0, 32, 24, 60.0);
  return v;
}

TEST(SceneJson, RoundTripKeepsViewsAndMetadata) {
  Scene scene;
  scene.directory = FreshDir("roundtrip");
  scene.views = {MakeView("a", 0), MakeView("b", 45)};
  scene.metadata["gt"] = {{"instances", "gt/instances.json"}};
  ASSERT_TRUE(WriteScene(scene).ok());
  absl::StatusOr<Scene> back = ReadScene(scene.directory);
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->views.size(), 2u);
  EXPECT_EQ(back->views[1].name, "b");
  EXPECT_EQ(back->views[1].mask, "masks/b.png");
  EXPECT_LT((back->views[1].camera.camera_from_world.ToMatrix() -
             scene.views[1].camera.camera_from_world.ToMatrix())
                .norm(),
            1e-12);
  EXPECT_EQ(back->metadata["gt"]["instances"], "gt/instances.json");
  EXPECT_FALSE(back->meters_per_unit.has_value());  // absent: unscaled, never guessed
  scene.meters_per_unit = 0.04;
  ASSERT_TRUE(WriteScene(scene).ok());
  back = ReadScene(scene.directory);
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->meters_per_unit, 0.04);
  EXPECT_FALSE(back->metadata.contains("meters_per_unit"));
  EXPECT_EQ(*ResolveView(*back, "b"), 1);
  EXPECT_EQ(*ResolveView(*back, "0"), 0);
  EXPECT_EQ(ResolveView(*back, "7").status().code(), absl::StatusCode::kNotFound);
}

void ExpectBadScene(const std::string& text, absl::string_view fragment) {
  absl::StatusOr<Scene> scene = ParseSceneJson(text, "scene.json");
  ASSERT_FALSE(scene.ok()) << text;
  EXPECT_NE(scene.status().message().find(fragment), std::string::npos) << scene.status();
}

TEST(SceneJson, RejectsMalformedManifests) {
  const std::string view =
      R"({"name":"v","width":4,"height":4,"fx":2,"fy":2,"cx":2,"cy":2,"camera_from_world":[[1,0,0,0],[0,1,0,0],[0,0,1,0]]})";
  ExpectBadScene("{", "not valid JSON");
  ExpectBadScene(R"({"format":"other","views":[]})", "format");
  // A "format" of another type is refused, not thrown (found by scene_json_fuzz).
  ExpectBadScene(R"({"format":1.0,"views":[]})", "format");
  ExpectBadScene(R"({"format":"instascene.scene/1","views":[)" + view + "," + view + "]}",
                 "duplicate view");
  ExpectBadScene(R"({"format":"instascene.scene/1","gaussians":"../x.ply","views":[]})",
                 "unsafe path");
  ExpectBadScene(R"({"format":"instascene.scene/1","views":[{"name":"v"}]})", "views[0]");
  std::string scaled = view;
  scaled.replace(scaled.find("[[1,0,0,0]"), 10, "[[2,0,0,0]");
  ExpectBadScene(R"({"format":"instascene.scene/1","views":[)" + scaled + "]}", "rotation");
  std::string escape = view;
  escape.insert(1, R"("image":"/etc/passwd",)");
  ExpectBadScene(R"({"format":"instascene.scene/1","views":[)" + escape + "]}", "unsafe path");
  for (const char* scale : {"0", "-1", "\"1\"", "null", "2e6"})
    ExpectBadScene(std::string(R"({"format":"instascene.scene/1","meters_per_unit":)") + scale +
                       R"(,"views":[]})",
                   "meters_per_unit");
  // Sizes are read as given, never wrapped or truncated.
  for (const char* width : {"4294967392", "0", "-3", "16385", "\"12\"", "12.5"}) {
    std::string sized = view;
    sized.replace(sized.find("\"width\":4"), 9, std::string("\"width\":") + width);
    ExpectBadScene(R"({"format":"instascene.scene/1","views":[)" + sized + "]}", "width");
  }
}

TEST(ImageIo, ImagesAndLabelMapsRoundTrip) {
  const std::string dir = FreshDir("images");
  Image image{4, 3, 3, std::vector<float>(36)};
  for (size_t i = 0; i < image.pixels.size(); ++i)
    image.pixels[i] = static_cast<float>(i % 17) / 16.0f;
  ASSERT_TRUE(WriteImage(dir + "/a.png", image).ok());
  absl::StatusOr<Image> back = ReadImage(dir + "/a.png");
  ASSERT_TRUE(back.ok()) << back.status();
  for (size_t i = 0; i < image.pixels.size(); ++i)
    EXPECT_NEAR(back->pixels[i], image.pixels[i], 1.0 / 255);
  // JPEG and 16-bit PNG encode in memory too; nothing but the files is left in the folder.
  ASSERT_TRUE(WriteImage(dir + "/a.jpg", image).ok());
  EXPECT_TRUE(ReadImage(dir + "/a.jpg").ok());
  ASSERT_TRUE(WriteImage(dir + "/a16.png", image, 16).ok());
  absl::StatusOr<Image> back16 = ReadImage(dir + "/a16.png");
  ASSERT_TRUE(back16.ok());
  EXPECT_NEAR(back16->pixels[5], image.pixels[5], 1.0 / 65535);
  EXPECT_EQ(WriteImage(dir + "/a.unknownformat", image).code(), absl::StatusCode::kInvalidArgument);
  size_t files = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++files;
  EXPECT_EQ(files, 3u);
  LabelMap labels{5, 2, {0, 1, 2, 300, 65535, 7, 7, 0, 9, 1000}};
  ASSERT_TRUE(WriteLabelMap(dir + "/m16.png", labels).ok());
  absl::StatusOr<LabelMap> labels_back = ReadLabelMap(dir + "/m16.png");
  ASSERT_TRUE(labels_back.ok()) << labels_back.status();
  EXPECT_EQ(labels_back->labels, labels.labels);
  // 8-bit label maps keep their ids.
  std::vector<uint8_t> ids = {0, 1, 2, 3, 255, 4};
  auto out = OIIO::ImageOutput::create(dir + "/m8.png");
  ASSERT_TRUE(out->open(dir + "/m8.png", OIIO::ImageSpec(3, 2, 1, OIIO::TypeDesc::UINT8)));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, ids.data()));
  out->close();
  absl::StatusOr<LabelMap> m8 = ReadLabelMap(dir + "/m8.png");
  ASSERT_TRUE(m8.ok()) << m8.status();
  EXPECT_EQ(m8->labels, (std::vector<uint16_t>{0, 1, 2, 3, 255, 4}));
  // An RGB image is not a label map; a truncated PNG is an error, not a crash.
  EXPECT_FALSE(ReadLabelMap(dir + "/a.png").ok());
  std::string bytes = *ReadFileBounded(dir + "/a.png", 1 << 20);
  ASSERT_TRUE(WriteFileAtomically(dir + "/cut.png", bytes.substr(0, bytes.size() / 2)).ok());
  EXPECT_FALSE(ReadImage(dir + "/cut.png").ok());
  EXPECT_EQ(ReadImage(dir + "/missing.png").status().code(), absl::StatusCode::kNotFound);
}

TEST(Scene, ViewImageSizeMustMatchCamera) {
  Scene scene;
  scene.directory = FreshDir("sizes");
  scene.views = {MakeView("a", 0)};
  fs::create_directories(scene.directory + "/images");
  ASSERT_TRUE(
      WriteImage(scene.Path("images/a.png"), Image{31, 24, 3, std::vector<float>(31 * 24 * 3)})
          .ok());
  absl::StatusOr<Image> image = ReadViewImage(scene, 0);
  ASSERT_FALSE(image.ok());
  EXPECT_NE(image.status().message().find("31x24"), std::string::npos) << image.status();
}

// A PNG that is only a signature and an IHDR chunk claiming width x height RGB 8-bit: what a
// hostile upload of a few bytes looks like.
std::string ForgedPngHeader(uint32_t width, uint32_t height) {
  auto crc32 = [](const std::string& bytes) {
    uint32_t c = 0xffffffffu;
    for (unsigned char b : bytes) {
      c ^= b;
      for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
    }
    return c ^ 0xffffffffu;
  };
  auto be32 = [](uint32_t v) {
    return std::string{static_cast<char>(v >> 24), static_cast<char>(v >> 16),
                       static_cast<char>(v >> 8), static_cast<char>(v)};
  };
  std::string chunk = "IHDR" + be32(width) + be32(height);
  chunk += std::string{8, 2, 0, 0, 0};      // 8 bits, RGB, deflate, no filter, no interlace
  const std::string data = "IDAT\x78\x9c";  // the start of a zlib stream, then nothing
  return std::string("\x89PNG\r\n\x1a\n", 8) + be32(13) + chunk + be32(crc32(chunk)) + be32(2) +
         data + be32(crc32(data));
}

TEST(ImageIo, ProbeReadsTheHeaderOnly) {
  const std::string dir = FreshDir("probe");
  ASSERT_TRUE(WriteImage(dir + "/rgb.png", Image{64, 48, 3, std::vector<float>(64 * 48 * 3)}).ok());
  ASSERT_TRUE(
      WriteLabelMap(dir + "/mask.png", LabelMap{64, 48, std::vector<uint16_t>(64 * 48)}).ok());
  absl::StatusOr<ImageHeader> rgb = ProbeImage(dir + "/rgb.png");
  ASSERT_TRUE(rgb.ok()) << rgb.status();
  EXPECT_EQ(rgb->width, 64);
  EXPECT_EQ(rgb->height, 48);
  EXPECT_EQ(rgb->channels, 3);
  EXPECT_FALSE(rgb->label_map);
  absl::StatusOr<ImageHeader> mask = ProbeImage(dir + "/mask.png");
  ASSERT_TRUE(mask.ok()) << mask.status();
  EXPECT_TRUE(mask->label_map);
  // From a prefix of the bytes (the upload check), and a prefix too short for the header.
  std::ifstream in(dir + "/rgb.png", std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  absl::StatusOr<ImageHeader> prefix = ProbeImageBytes(bytes.substr(0, 64), "rgb.png");
  ASSERT_TRUE(prefix.ok()) << prefix.status();
  EXPECT_EQ(prefix->width, 64);
  absl::StatusOr<ImageHeader> cut = ProbeImageBytes(bytes.substr(0, 12), "rgb.png");
  EXPECT_EQ(cut.status().code(), absl::StatusCode::kDataLoss) << cut.status();
  // Headers beyond the limits, and what is not a regular file.
  ASSERT_TRUE(WriteFileAtomically(dir + "/huge.png", ForgedPngHeader(16000, 16000)).ok());
  absl::StatusOr<ImageHeader> huge = ProbeImage(dir + "/huge.png");
  ASSERT_FALSE(huge.ok());
  EXPECT_NE(huge.status().message().find("16000x16000"), std::string::npos) << huge.status();
  EXPECT_FALSE(ReadImage(dir + "/huge.png").ok());
  EXPECT_EQ(ProbeImage(dir).status().code(), absl::StatusCode::kNotFound);
}

TEST(Scene, AViewImageIsCheckedAgainstItsCameraBeforeDecoding) {
  // 8000 x 8000 is within the limits, so only the camera check can stop it; decoding first would
  // allocate 768 MB and then fail on the missing pixel data (DATA_LOSS).
  Scene scene;
  scene.directory = FreshDir("forged");
  scene.views = {MakeView("a", 0)};
  fs::create_directories(scene.directory + "/images");
  fs::create_directories(scene.directory + "/masks");
  ASSERT_TRUE(WriteFileAtomically(scene.Path("images/a.png"), ForgedPngHeader(8000, 8000)).ok());
  ASSERT_TRUE(WriteFileAtomically(scene.Path("masks/a.png"), ForgedPngHeader(8000, 8000)).ok());
  absl::StatusOr<Image> image = ReadViewImage(scene, 0);
  EXPECT_EQ(image.status().code(), absl::StatusCode::kInvalidArgument) << image.status();
  EXPECT_NE(image.status().message().find("camera is 32x24"), std::string::npos);
  absl::StatusOr<LabelMap> mask = ReadViewMask(scene, 0);
  EXPECT_EQ(mask.status().code(), absl::StatusCode::kInvalidArgument) << mask.status();
  EXPECT_EQ(CheckViewFiles(scene).code(), absl::StatusCode::kInvalidArgument);
  // Right sizes pass; an RGB "mask" does not.
  ASSERT_TRUE(
      WriteImage(scene.Path("images/a.png"), Image{32, 24, 3, std::vector<float>(32 * 24 * 3)})
          .ok());
  ASSERT_TRUE(
      WriteLabelMap(scene.Path("masks/a.png"), LabelMap{32, 24, std::vector<uint16_t>(32 * 24)})
          .ok());
  EXPECT_TRUE(CheckViewFiles(scene).ok()) << CheckViewFiles(scene);
  ASSERT_TRUE(
      WriteImage(scene.Path("masks/a.png"), Image{32, 24, 3, std::vector<float>(32 * 24 * 3)})
          .ok());
  const absl::Status rgb_mask = CheckViewFiles(scene);
  EXPECT_NE(rgb_mask.message().find("single-channel"), std::string::npos) << rgb_mask;
}

// Writes a tiny COLMAP model in the binary or text format.
void WriteColmap(const std::string& dir, bool binary, int model_id,
                 const std::vector<double>& params) {
  const char* kNames[] = {"SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL"};
  const double q[4] = {0.9238795, 0, 0.3826834, 0}, t[3] = {0.5, -1, 2};
  if (binary) {
    std::string cams, imgs;
    auto put = [](std::string* s, const auto& v) {
      s->append(reinterpret_cast<const char*>(&v), sizeof(v));
    };
    put(&cams, uint64_t{1});
    put(&cams, uint32_t{3});
    put(&cams, int32_t{model_id});
    put(&cams, uint64_t{64});
    put(&cams, uint64_t{48});
    for (double p : params) put(&cams, p);
    put(&imgs, uint64_t{2});
    for (const char* name : {"b.png", "a.png"}) {
      put(&imgs, uint32_t{1});
      for (double v : q) put(&imgs, v);
      for (double v : t) put(&imgs, v);
      put(&imgs, uint32_t{3});
      imgs.append(name, std::strlen(name) + 1);
      put(&imgs, uint64_t{1});
      put(&imgs, 1.0);
      put(&imgs, 2.0);
      put(&imgs, int64_t{-1});
    }
    ASSERT_TRUE(WriteFileAtomically(dir + "/cameras.bin", cams).ok());
    ASSERT_TRUE(WriteFileAtomically(dir + "/images.bin", imgs).ok());
  } else {
    std::ofstream cams(dir + "/cameras.txt");
    cams << "# Camera list\n3 " << kNames[model_id] << " 64 48";
    for (double p : params) cams << " " << p;
    cams << "\n";
    std::ofstream imgs(dir + "/images.txt");
    imgs << "# Image list\n";
    for (const char* name : {"b.png", "a.png"}) {
      imgs << "1 " << q[0] << " " << q[1] << " " << q[2] << " " << q[3] << " " << t[0] << " "
           << t[1] << " " << t[2] << " 3 " << name << "\n1.0 2.0 -1\n";
    }
  }
}

TEST(Importers, ColmapBinaryAndTextAgree) {
  for (bool binary : {true, false}) {
    const std::string dir = FreshDir(binary ? "colmap_bin" : "colmap_txt");
    WriteColmap(dir, binary, 1, {50, 52, 32, 24});
    absl::StatusOr<ImportedCameras> imported = ImportColmapModel(dir);
    ASSERT_TRUE(imported.ok()) << imported.status();
    ASSERT_EQ(imported->views.size(), 2u);
    EXPECT_EQ(imported->views[0].name, "a");  // sorted by name
    const PinholeCamera& c = imported->views[0].camera;
    EXPECT_EQ(c.width, 64);
    EXPECT_DOUBLE_EQ(c.fy, 52);
    EXPECT_NEAR(c.camera_from_world.translation.y(), -1.0, 1e-12);
    EXPECT_NEAR(c.camera_from_world.rotation(0, 2), std::sin(M_PI / 4), 1e-6);
  }
}

TEST(Importers, ColmapDistortedModelNeedsExplicitUndistortion) {
  const std::string dir = FreshDir("colmap_radial");
  WriteColmap(dir, true, 2, {50, 32, 24, 0.01});
  absl::StatusOr<ImportedCameras> imported = ImportColmapModel(dir);
  ASSERT_FALSE(imported.ok());
  EXPECT_NE(imported.status().message().find("SIMPLE_RADIAL"), std::string::npos);
  ImportOptions options;
  options.assume_undistorted = true;
  imported = ImportColmapModel(dir, options);
  ASSERT_TRUE(imported.ok()) << imported.status();
  EXPECT_DOUBLE_EQ(imported->views[0].camera.fy, 50);
  // A truncated binary model is an error.
  std::string bytes = *ReadFileBounded(dir + "/images.bin", 1 << 20);
  ASSERT_TRUE(WriteFileAtomically(dir + "/images.bin", bytes.substr(0, 40)).ok());
  EXPECT_FALSE(ImportColmapModel(dir, options).ok());
}

TEST(Importers, RealInstantNgpFoxSkipsMissingFrames) {
  const std::string path =
      std::string(INSTASCENE_SHARED_DIR) + "/data/fox_instant_ngp/transforms.json";
  if (!fs::exists(path)) GTEST_SKIP() << "shared data missing";
  absl::StatusOr<ImportedCameras> strict = ImportTransformsJson(path);
  ASSERT_FALSE(strict.ok());
  EXPECT_NE(strict.status().message().find("distortion"), std::string::npos);
  ImportOptions options;
  options.assume_undistorted = true;
  // The original file points at the full-size images, of which the repository keeps none here.
  EXPECT_FALSE(ImportTransformsJson(path, options).ok());
  absl::StatusOr<ImportedCameras> fox = ImportTransformsJson(
      std::string(INSTASCENE_SHARED_DIR) + "/data/fox_instant_ngp/transforms_images_2.json",
      options);
  ASSERT_TRUE(fox.ok()) << fox.status();
  EXPECT_EQ(fox->views.size(), 50u);
  EXPECT_EQ(fox->views.front().name, "0001");
  const PinholeCamera& c = fox->views.front().camera;
  EXPECT_EQ(c.width, 540);
  EXPECT_EQ(c.height, 960);
  // Frame 0001: camera centre is the matrix translation; OpenCV forward is the GL -z column.
  EXPECT_NEAR(c.CenterInWorld().x(), 3.168359405609479, 1e-6);
  const Eigen::Vector3d forward = c.camera_from_world.rotation.row(2);
  EXPECT_NEAR(forward.x(), -0.4420900262071262, 1e-6);
  // All 50 cameras look roughly at a common point (the fox): their optical axes pass near the
  // centroid of the camera centres' look-at target.
  int looking_inward = 0;
  Eigen::Vector3d mean_center = Eigen::Vector3d::Zero();
  for (const SceneView& v : fox->views) mean_center += v.camera.CenterInWorld() / fox->views.size();
  for (const SceneView& v : fox->views) {
    const Eigen::Vector3d f = v.camera.camera_from_world.rotation.row(2);
    if (f.dot(mean_center - v.camera.CenterInWorld()) > 0) ++looking_inward;
  }
  EXPECT_GE(looking_inward, 45);
}

}  // namespace
}  // namespace instascene
