#include <gtest/gtest.h>
#include <sys/stat.h>

#include "common/scene/scene.h"

#include <filesystem>
#include <fstream>
#include <random>

#include "common/core/status.h"
#include "common/core/testing/files.h"
#include "common/core/testing/temp_dir.h"
#include "common/store/blob_store.h"
#include "common/store/manifest.h"
#include "common/store/testing/blob_store_conformance.h"
#include "common/synth/scene_writer.h"

namespace instascene::store {
namespace {
namespace fs = std::filesystem;
using instascene::testing::CountFiles;
using instascene::testing::RandomBytes;
using store::testing::BlobStoreConformanceTest;

std::unique_ptr<FilesystemBlobStore> OpenStore(const std::string& root, StoreOptions options = {}) {
  auto store = FilesystemBlobStore::Open(root, options);
  EXPECT_TRUE(store.ok()) << store.status();
  return std::move(*store);
}

TEST(DigestTest, KnownVectors) {
  EXPECT_EQ(ComputeDigest("").hash,
            "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(ComputeDigest("abc").hash,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(ComputeDigest("abc").size_bytes, 3);
  // Incremental hashing equals one-shot hashing at any split.
  const std::string data = RandomBytes(10000, 1);
  for (size_t split : {0, 1, 4097, 9999}) {
    Sha256 sha;
    sha.Update(absl::string_view(data).substr(0, split));
    sha.Update(absl::string_view(data).substr(split));
    EXPECT_EQ(sha.HexDigest(), ComputeDigest(data).hash);
  }
  auto parsed = ParseDigest(ComputeDigest("abc").ToString());
  ASSERT_TRUE(parsed.ok());
  EXPECT_EQ(*parsed, ComputeDigest("abc"));
  EXPECT_FALSE(ParseDigest("xyz/3").ok());
  EXPECT_FALSE(ParseDigest(ComputeDigest("abc").hash).ok());
}

class FilesystemBackend : public store::testing::BlobStoreBackend {
 public:
  absl::StatusOr<std::unique_ptr<BlobStore>> Open(const StoreOptions& options) override {
    ASSIGN_OR_RETURN(std::unique_ptr<FilesystemBlobStore> store,
                     FilesystemBlobStore::Open(temp_.str(), options));
    return std::unique_ptr<BlobStore>(std::move(store));
  }

 private:
  instascene::testing::ScopedTempDir temp_{"fs_conformance"};
};

INSTANTIATE_TEST_SUITE_P(Filesystem, BlobStoreConformanceTest,
                         ::testing::Values(store::testing::BlobStoreBackendFactory{
                             "filesystem", [] { return std::make_unique<FilesystemBackend>(); }}),
                         store::testing::BackendName);

TEST(BlobStoreTest, RejectedWritesLeaveNoFiles) {
  const instascene::testing::ScopedTempDir temp("store_reject");
  const std::string root = temp.str();
  StoreOptions options;
  options.max_blob_bytes = 100;
  auto store = OpenStore(root, options);
  const std::string data = RandomBytes(50, 4);
  Digest wrong = ComputeDigest(data);
  wrong.hash[0] = wrong.hash[0] == 'a' ? 'b' : 'a';
  EXPECT_FALSE(store->Put(wrong, data).ok());
  const std::string big = RandomBytes(101, 5);
  EXPECT_FALSE(store->Put(ComputeDigest(big), big).ok());
  EXPECT_FALSE(store->Append(ComputeDigest(big), 0, big).ok());
  std::string corrupt = RandomBytes(60, 7);
  const Digest d = ComputeDigest(corrupt);
  corrupt[10] ^= 1;
  ASSERT_TRUE(store->Append(d, 0, corrupt).ok());
  EXPECT_FALSE(store->FinishUpload(d).ok());
  EXPECT_EQ(CountFiles(root), 0u);
}

TEST(ManifestTest, RoundTripAndMalformed) {
  Manifest m;
  m.kind = "scene";
  m.files["scene.json"] = ComputeDigest("{}");
  m.files["images/a.png"] = ComputeDigest("a");
  m.metadata["views"] = 1;
  const std::string bytes = SerializeManifest(m);
  auto back = ParseManifest(bytes, "m");
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->files, m.files);
  EXPECT_EQ(SerializeManifest(*back), bytes);
  for (const std::string& bad :
       {std::string("not json"), std::string("[]"), std::string("{\"format\":\"x\"}"),
        std::string("{\"format\":1}"),  // a format of another type: refused, not thrown
        std::string(R"({"format":"instascene.manifest/1","kind":"scene","files":{"../x":"a/1"}})"),
        std::string(R"({"format":"instascene.manifest/1","kind":"scene","files":{"x":"zz/1"}})"),
        std::string(R"({"format":"instascene.manifest/1","kind":"scene","files":{"/etc/x":")") +
            ComputeDigest("a").ToString() + "\"}}"}) {
    const auto parsed = ParseManifest(bad, "upload");
    EXPECT_EQ(parsed.status().code(), absl::StatusCode::kInvalidArgument) << bad;
    EXPECT_NE(parsed.status().message().find("upload: malformed manifest"), std::string::npos);
  }
}

TEST(ManifestTest, SceneUploadSendsOnlyWhatIsMissing) {
  const instascene::testing::ScopedTempDir temp("store_scene");
  const std::string root = temp.str();
  const std::string scene_dir = (fs::path(root) / "scene").string();
  absl::StatusOr<ClutterScene> generated = GenerateClutterScene(*ClutterPreset("tiny"));
  ASSERT_TRUE(generated.ok());
  ASSERT_TRUE(WriteClutterScene(*generated, scene_dir).ok());
  auto store = OpenStore((fs::path(root) / "store").string());
  auto manifest = SceneManifestFromDirectory(scene_dir);
  ASSERT_TRUE(manifest.ok()) << manifest.status();
  for (const auto& [path, d] : manifest->files) EXPECT_NE(path.rfind("gt/", 0), 0u) << path;
  auto first = UploadManifest(*store, *manifest, scene_dir);
  ASSERT_TRUE(first.ok()) << first.status();
  EXPECT_GT(first->files_sent, 2);
  auto second = UploadManifest(*store, *manifest, scene_dir);
  ASSERT_TRUE(second.ok());
  EXPECT_EQ(second->files_sent, 0);
  EXPECT_EQ(second->bytes_sent, 0);
  EXPECT_EQ(second->manifest, first->manifest);
  auto read = ReadManifest(*store, first->manifest);
  ASSERT_TRUE(read.ok());
  EXPECT_TRUE(ValidateSceneManifest(*store, *read).ok());
  // Limits: the Gaussian count comes from the splat's header in the store.
  SceneLimits few;
  few.max_gaussians = 10;
  const absl::Status gaussians = ValidateSceneManifest(*store, *read, few);
  EXPECT_EQ(gaussians.code(), absl::StatusCode::kResourceExhausted) << gaussians;
  EXPECT_NE(gaussians.message().find("Gaussians"), std::string::npos) << gaussians;
  few = SceneLimits{};
  few.max_views = 1;
  EXPECT_EQ(ValidateSceneManifest(*store, *read, few).code(), absl::StatusCode::kResourceExhausted);
  few = SceneLimits{};
  few.max_total_pixels = 100;
  EXPECT_EQ(ValidateSceneManifest(*store, *read, few).code(), absl::StatusCode::kResourceExhausted);
  // Materialised, it is the same scene.
  const std::string copy = (fs::path(root) / "copy").string();
  ASSERT_TRUE(MaterializeManifest(*store, *read, copy).ok());
  auto again = SceneManifestFromDirectory(copy);
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_EQ(again->files, manifest->files);
  // A manifest that drops a referenced file is not a scene.
  Manifest broken = *read;
  broken.files.erase(broken.files.begin()->first == "scene.json" ? std::next(broken.files.begin())
                                                                 : broken.files.begin());
  const absl::Status s = ValidateSceneManifest(*store, broken);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  // Only regular files inside the scene folder are uploaded: a FIFO would block for ever, a
  // symlink out of the folder would share a file the user did not mean to.
  auto scene = ReadScene(copy);
  const std::string mask = scene->Path(scene->views[0].mask);
  fs::remove(mask);
  ASSERT_EQ(::mkfifo(mask.c_str(), 0644), 0);
  auto fifo = SceneManifestFromDirectory(copy);
  EXPECT_EQ(fifo.status().code(), absl::StatusCode::kInvalidArgument) << fifo.status();
  EXPECT_NE(fifo.status().message().find("not a regular file"), std::string::npos);
  fs::remove(mask);
  fs::create_symlink(fs::path(root) / "scene" / scene->views[0].mask, mask);  // outside: refused
  auto outside = SceneManifestFromDirectory(copy);
  EXPECT_EQ(outside.status().code(), absl::StatusCode::kInvalidArgument) << outside.status();
  EXPECT_NE(outside.status().message().find("outside the scene folder"), std::string::npos);
}

TEST(BlobStoreTest, ATenantsBytesAreTheSizesOfItsGrants) {
  instascene::testing::ScopedTempDir temp("tenant_bytes");
  auto store = FilesystemBlobStore::Open(temp.str(), StoreOptions{});
  ASSERT_TRUE(store.ok()) << store.status();
  EXPECT_EQ(*(*store)->TenantBytes("acme"), 0);  // no grants yet
  const std::string a = "seven b", b = "eleven byte";
  for (const std::string* s : {&a, &b}) ASSERT_TRUE((*store)->Put(ComputeDigest(*s), *s).ok());
  ASSERT_TRUE((*store)->Grant("acme", {ComputeDigest(a), ComputeDigest(b)}).ok());
  ASSERT_TRUE((*store)->Grant("acme", {ComputeDigest(a)}).ok());  // granted twice: once
  ASSERT_TRUE((*store)->Grant("beta", {ComputeDigest(a)}).ok());
  EXPECT_EQ(*(*store)->TenantBytes("acme"), 18);
  EXPECT_EQ(*(*store)->TenantBytes("beta"), 7);
  // A removed blob's grants stay until the collector removes them (garbage_collection.h).
  ASSERT_TRUE((*store)->Remove(ComputeDigest(b)).ok());
  auto grants = (*store)->ListGrants();
  ASSERT_TRUE(grants.ok()) << grants.status();
  ASSERT_EQ(grants->size(), 3u);
  EXPECT_EQ((*grants)[0].tenant, "acme");
  EXPECT_EQ((*grants)[2].tenant, "beta");
  EXPECT_EQ((*grants)[2].digest, ComputeDigest(a));
  EXPECT_EQ(*(*store)->TenantBytes("acme"), 18);
  ASSERT_TRUE((*store)->RemoveGrant("acme", ComputeDigest(b)).ok());
  ASSERT_TRUE((*store)->RemoveGrant("acme", ComputeDigest(b)).ok());  // absent: not an error
  EXPECT_EQ(*(*store)->TenantBytes("acme"), 7);
  EXPECT_EQ((*store)->ListGrants()->size(), 2u);
  EXPECT_EQ((*store)->TenantBytes("../x").status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ((*store)->RemoveGrant("../x", ComputeDigest(a)).code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(BlobStoreTest, OneProcessOwnsAStoreFolder) {
  const instascene::testing::ScopedTempDir temp("store_lock");
  auto first = FilesystemBlobStore::Open(temp.str(), StoreOptions{});
  ASSERT_TRUE(first.ok());
  auto second = FilesystemBlobStore::Open(temp.str(), StoreOptions{});
  EXPECT_EQ(second.status().code(), absl::StatusCode::kFailedPrecondition) << second.status();
  EXPECT_NE(second.status().message().find("in use by another process"), std::string::npos);
  first->reset();
  EXPECT_TRUE(FilesystemBlobStore::Open(temp.str(), StoreOptions{}).ok());  // released
}

TEST(BlobStoreTest, AbandonedUploadsExpireAndCountInTheStatistics) {
  const instascene::testing::ScopedTempDir temp("store_ttl");
  const std::string bytes(1000, 'u');
  const Digest fresh = ComputeDigest(bytes), stale = ComputeDigest(bytes + "x");
  StoreOptions options;
  options.upload_ttl_seconds = 3600;
  {
    auto store = FilesystemBlobStore::Open(temp.str(), options);
    ASSERT_TRUE(store.ok());
    ASSERT_TRUE((*store)->Append(fresh, 0, bytes.substr(0, 300)).ok());
    ASSERT_TRUE((*store)->Append(stale, 0, bytes.substr(0, 400)).ok());
    const StoreStats stats = *(*store)->Stats();
    EXPECT_EQ(stats.partial_uploads, 2);
    EXPECT_EQ(stats.partial_bytes, 700);
    EXPECT_EQ(stats.expired_uploads, 0);
  }
  // The stale upload was last written two hours ago (set, not waited for).
  for (const auto& e : std::filesystem::directory_iterator(temp.str() + "/uploads")) {
    if (e.path().filename().string().rfind(stale.hash, 0) == 0)
      std::filesystem::last_write_time(
          e.path(), std::filesystem::file_time_type::clock::now() - std::chrono::hours(2));
  }
  auto store = FilesystemBlobStore::Open(temp.str(), options);  // sweeps at open
  ASSERT_TRUE(store.ok());
  const StoreStats stats = *(*store)->Stats();
  EXPECT_EQ(stats.partial_uploads, 1);
  EXPECT_EQ(stats.partial_bytes, 300);
  EXPECT_EQ(stats.expired_uploads, 1);
  EXPECT_EQ(*(*store)->CommittedSize(stale), 0);    // starts over
  EXPECT_EQ(*(*store)->CommittedSize(fresh), 300);  // resumes
  ASSERT_TRUE((*store)->Append(fresh, 300, bytes.substr(300)).ok());
  ASSERT_TRUE((*store)->FinishUpload(fresh).ok());
  EXPECT_EQ(*(*store)->Read(fresh), bytes);
  EXPECT_EQ((*store)->Stats()->partial_uploads, 0);
}

}  // namespace
}  // namespace instascene::store
