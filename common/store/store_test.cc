#include <gtest/gtest.h>
#include <sys/stat.h>

#include "common/scene/scene.h"

#include <filesystem>
#include <fstream>
#include <random>

#include "common/core/testing/files.h"
#include "common/core/testing/temp_dir.h"
#include "common/store/blob_store.h"
#include "common/store/manifest.h"
#include "common/synth/scene_writer.h"

namespace instascene::store {
namespace {
namespace fs = std::filesystem;
using instascene::testing::CountFiles;
using instascene::testing::RandomBytes;

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

TEST(BlobStoreTest, PutReadFindMissing) {
  const testing::ScopedTempDir temp("store_put");
  auto store = OpenStore(temp.str());
  const std::string a = RandomBytes(1000, 2), b = RandomBytes(10, 3);
  const Digest da = ComputeDigest(a), db = ComputeDigest(b);
  auto missing = store->FindMissing({da, db});
  ASSERT_TRUE(missing.ok());
  EXPECT_EQ(missing->size(), 2u);
  ASSERT_TRUE(store->Put(da, a).ok());
  ASSERT_TRUE(store->Put(da, a).ok());  // idempotent
  missing = store->FindMissing({da, db});
  ASSERT_EQ(missing->size(), 1u);
  EXPECT_EQ((*missing)[0], db);
  EXPECT_EQ(*store->Read(da), a);
  EXPECT_EQ(*store->Read(da, 10, 20), a.substr(10, 20));
  EXPECT_EQ(store->Read(db).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store->Stats()->blob_count, 1);
}

TEST(BlobStoreTest, RejectsWrongDigestAndOversizedBlobsLeavingNothing) {
  const testing::ScopedTempDir temp("store_reject");
  const std::string root = temp.str();
  StoreOptions options;
  options.max_blob_bytes = 100;
  auto store = OpenStore(root, options);
  const std::string data = RandomBytes(50, 4);
  Digest wrong = ComputeDigest(data);
  wrong.hash[0] = wrong.hash[0] == 'a' ? 'b' : 'a';
  const absl::Status s = store->Put(wrong, data);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("digest mismatch"), std::string::npos) << s;
  const std::string big = RandomBytes(101, 5);
  EXPECT_EQ(store->Put(ComputeDigest(big), big).code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(store->Append(ComputeDigest(big), 0, big).status().code(),
            absl::StatusCode::kResourceExhausted);
  Digest bad_size = ComputeDigest(data);
  bad_size.size_bytes = 49;
  EXPECT_EQ(store->Put(bad_size, data).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(store->Put(Digest{"nothex", 3}, "abc").code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(CountFiles(root), 0u);
}

TEST(BlobStoreTest, ResumableUpload) {
  const testing::ScopedTempDir temp("store_resume");
  const std::string root = temp.str();
  const std::string data = RandomBytes(300000, 6);
  const Digest d = ComputeDigest(data);
  {
    auto store = OpenStore(root);
    EXPECT_EQ(*store->CommittedSize(d), 0);
    EXPECT_EQ(*store->Append(d, 0, absl::string_view(data).substr(0, 100000)), 100000);
    // A chunk at the wrong offset is refused with the offset to resume at.
    const auto wrong = store->Append(d, 5, "xyz");
    EXPECT_EQ(wrong.status().code(), absl::StatusCode::kFailedPrecondition);
    EXPECT_NE(wrong.status().message().find("100000 bytes committed"), std::string::npos);
  }
  // The "process" restarts: the committed prefix is still there.
  auto store = OpenStore(root);
  EXPECT_EQ(*store->CommittedSize(d), 100000);
  EXPECT_FALSE(store->FindMissing({d})->empty());
  EXPECT_EQ(*store->Append(d, 100000, absl::string_view(data).substr(100000)), 300000);
  ASSERT_TRUE(store->FinishUpload(d).ok());
  EXPECT_TRUE(store->FindMissing({d})->empty());
  EXPECT_EQ(*store->Read(d), data);
  EXPECT_EQ(*store->CommittedSize(d), 300000);
}

TEST(BlobStoreTest, FinishWithWrongBytesDiscardsTheUpload) {
  const testing::ScopedTempDir temp("store_finish_bad");
  const std::string root = temp.str();
  auto store = OpenStore(root);
  std::string data = RandomBytes(5000, 7);
  const Digest d = ComputeDigest(data);
  data[100] ^= 1;
  ASSERT_TRUE(store->Append(d, 0, data).ok());
  const absl::Status s = store->FinishUpload(d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("digest mismatch"), std::string::npos);
  EXPECT_EQ(CountFiles(root), 0u);
  EXPECT_EQ(*store->CommittedSize(d), 0);
}

TEST(BlobStoreTest, PutFileAndGetFileRoundTrip) {
  const testing::ScopedTempDir temp("store_files");
  const std::string root = temp.str();
  StoreOptions options;
  options.max_batch_bytes = 1000;  // force the chunked path for the big file
  auto store = OpenStore(fs::path(root) / "store", options);
  for (size_t size : {0, 10, 999, 3 << 20}) {
    const std::string data = RandomBytes(size, size);
    const std::string path = (fs::path(root) / "in.bin").string();
    std::ofstream(path, std::ios::binary) << data;
    const Digest d = *DigestFile(path);
    EXPECT_EQ(d, ComputeDigest(data));
    int64_t last = -1;
    ASSERT_TRUE(store->PutFile(d, path, [&](int64_t done, int64_t) { last = done; }).ok());
    EXPECT_EQ(last, static_cast<int64_t>(size));
    const std::string out = (fs::path(root) / "out.bin").string();
    ASSERT_TRUE(store->GetFile(d, out).ok());
    std::ifstream in(out, std::ios::binary);
    EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), data);
  }
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
  const testing::ScopedTempDir temp("store_scene");
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

TEST(BlobStoreTest, OneProcessOwnsAStoreFolder) {
  const testing::ScopedTempDir temp("store_lock");
  auto first = FilesystemBlobStore::Open(temp.str(), StoreOptions{});
  ASSERT_TRUE(first.ok());
  auto second = FilesystemBlobStore::Open(temp.str(), StoreOptions{});
  EXPECT_EQ(second.status().code(), absl::StatusCode::kFailedPrecondition) << second.status();
  EXPECT_NE(second.status().message().find("in use by another process"), std::string::npos);
  first->reset();
  EXPECT_TRUE(FilesystemBlobStore::Open(temp.str(), StoreOptions{}).ok());  // released
}

}  // namespace
}  // namespace instascene::store
