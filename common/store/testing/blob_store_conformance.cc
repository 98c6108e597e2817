#include "common/store/testing/blob_store_conformance.h"

#include <filesystem>
#include <fstream>
#include <thread>

#include "common/core/testing/files.h"
#include "common/core/testing/temp_dir.h"

namespace instascene::store::testing {
namespace {
using instascene::testing::RandomBytes;
constexpr int64_t kMiB = int64_t{1} << 20;

std::string Slice(const std::string& s, int64_t from, int64_t n) {
  return s.substr(static_cast<size_t>(from), static_cast<size_t>(n));
}

}  // namespace

std::unique_ptr<BlobStore> BlobStoreConformanceTest::Open(const StoreOptions& options) {
  absl::StatusOr<std::unique_ptr<BlobStore>> store = backend_->Open(options);
  EXPECT_TRUE(store.ok()) << store.status();
  return store.ok() ? std::move(*store) : nullptr;
}

TEST_P(BlobStoreConformanceTest, PutReadFindMissingStats) {
  auto store = Open();
  ASSERT_NE(store, nullptr);
  const std::string a = RandomBytes(1000, 2), b = RandomBytes(10, 3), empty;
  const Digest da = ComputeDigest(a), db = ComputeDigest(b), de = ComputeDigest(empty);
  EXPECT_EQ(store->FindMissing({da, db, de})->size(), 3u);
  ASSERT_TRUE(store->Put(da, a).ok());
  ASSERT_TRUE(store->Put(da, a).ok());  // idempotent
  ASSERT_TRUE(store->Put(de, empty).ok());
  const auto missing = store->FindMissing({da, db, de});
  ASSERT_TRUE(missing.ok()) << missing.status();
  ASSERT_EQ(missing->size(), 1u);
  EXPECT_EQ((*missing)[0], db);
  EXPECT_EQ(*store->Read(da), a);
  EXPECT_EQ(*store->Read(da, 10, 20), a.substr(10, 20));
  EXPECT_EQ(*store->Read(da, 990, 100), a.substr(990));  // a limit past the end stops there
  EXPECT_EQ(*store->Read(da, 1000), "");
  EXPECT_EQ(*store->Read(de), "");
  EXPECT_EQ(store->Read(da, 1001).status().code(), absl::StatusCode::kOutOfRange);
  EXPECT_EQ(store->Read(db).status().code(), absl::StatusCode::kNotFound);
  const auto stats = store->Stats();
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(stats->blob_count, 2);
  EXPECT_EQ(stats->total_bytes, 1000);
}

TEST_P(BlobStoreConformanceTest, FindMissingOfManyKeepsTheRequestOrder) {
  auto store = Open();
  ASSERT_NE(store, nullptr);
  std::vector<Digest> all, expected;
  for (int i = 0; i < 100; ++i) {
    const std::string b = RandomBytes(64, 1000 + static_cast<uint64_t>(i));
    all.push_back(ComputeDigest(b));
    if (i % 3 == 0)
      ASSERT_TRUE(store->Put(all.back(), b).ok());
    else
      expected.push_back(all.back());
  }
  const auto missing = store->FindMissing(all);
  ASSERT_TRUE(missing.ok()) << missing.status();
  EXPECT_EQ(*missing, expected);
}

TEST_P(BlobStoreConformanceTest, RejectsWrongDigestOversizedAndMalformedLeavingNothing) {
  StoreOptions options;
  options.max_blob_bytes = 100;
  auto store = Open(options);
  ASSERT_NE(store, nullptr);
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
  EXPECT_EQ(store->FindMissing({Digest{"nothex", 3}}).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(store->FindMissing({wrong, ComputeDigest(data)})->size(), 2u);
  EXPECT_EQ(store->Stats()->blob_count, 0);
}

TEST_P(BlobStoreConformanceTest, InterruptedUploadResumesAfterARestart) {
  const std::string data = RandomBytes(12 * kMiB + 7, 6);
  const Digest d = ComputeDigest(data);
  const int64_t reached = 6 * kMiB + 3;
  {
    auto store = Open();
    ASSERT_NE(store, nullptr);
    EXPECT_EQ(*store->CommittedSize(d), 0);
    for (int64_t at = 0; at < reached;) {
      const int64_t n = std::min(kMiB, reached - at);
      const auto next = store->Append(d, at, Slice(data, at, n));
      ASSERT_TRUE(next.ok()) << next.status();
      ASSERT_EQ(*next, at + n);
      at = *next;
    }
    EXPECT_EQ(*store->CommittedSize(d), reached);
    // A chunk at the wrong offset is refused with the offset to resume at.
    const auto wrong = store->Append(d, 5, "xyz");
    EXPECT_EQ(wrong.status().code(), absl::StatusCode::kFailedPrecondition);
    EXPECT_NE(wrong.status().message().find(std::to_string(reached) + " bytes committed"),
              std::string::npos)
        << wrong.status();
    // Finishing early is refused and keeps what was sent.
    EXPECT_FALSE(store->FinishUpload(d).ok());
    EXPECT_EQ(*store->CommittedSize(d), reached);
    EXPECT_FALSE(store->FindMissing({d})->empty());
  }
  // The process restarts: the committed prefix (less what the backend had only buffered) is there.
  auto store = Open();
  ASSERT_NE(store, nullptr);
  int64_t at = *store->CommittedSize(d);
  EXPECT_LE(at, reached);
  EXPECT_GE(at, reached - backend_->resume_loss_bytes());
  EXPECT_FALSE(store->FindMissing({d})->empty());
  while (at < static_cast<int64_t>(data.size())) {
    const int64_t n = std::min(kMiB, static_cast<int64_t>(data.size()) - at);
    const auto next = store->Append(d, at, Slice(data, at, n));
    ASSERT_TRUE(next.ok()) << next.status();
    at = *next;
  }
  // (The remote store publishes as soon as every byte is committed; verified all the same.)
  ASSERT_TRUE(store->FinishUpload(d).ok());
  EXPECT_TRUE(store->FindMissing({d})->empty());
  EXPECT_EQ(*store->Read(d), data);
  EXPECT_EQ(*store->CommittedSize(d), d.size_bytes);
  EXPECT_TRUE(store->FinishUpload(d).ok());  // finishing twice is harmless
}

TEST_P(BlobStoreConformanceTest, UploadWithWrongBytesIsDiscarded) {
  auto store = Open();
  ASSERT_NE(store, nullptr);
  for (const int64_t size : {int64_t{5000}, 11 * kMiB}) {
    std::string data = RandomBytes(static_cast<size_t>(size), 7);
    const Digest d = ComputeDigest(data);
    data[100] ^= 1;
    // Refused at the last append (a backend that publishes once complete) or at FinishUpload.
    absl::Status s;
    for (int64_t at = 0; at < size && s.ok(); at += kMiB)
      s = store->Append(d, at, Slice(data, at, std::min(kMiB, size - at))).status();
    if (s.ok()) s = store->FinishUpload(d);
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
    EXPECT_NE(s.message().find("digest mismatch"), std::string::npos) << s;
    EXPECT_FALSE(store->FindMissing({d})->empty());
    EXPECT_EQ(*store->CommittedSize(d), 0);  // a wrong upload is not kept, not even to resume
  }
  EXPECT_EQ(store->Stats()->blob_count, 0);
}

TEST_P(BlobStoreConformanceTest, PutFileAndGetFileRoundTrip) {
  const instascene::testing::ScopedTempDir temp("conformance_files");
  StoreOptions options;
  options.max_batch_bytes = 1000;  // forces the chunked path for larger files
  auto store = Open(options);
  ASSERT_NE(store, nullptr);
  for (const size_t size : {size_t{0}, size_t{10}, size_t{999}, size_t{11 * kMiB + 5}}) {
    const std::string data = RandomBytes(size, size);
    const std::string path = temp.str() + "/in.bin";
    std::ofstream(path, std::ios::binary) << data;
    const Digest d = *DigestFile(path);
    EXPECT_EQ(d, ComputeDigest(data));
    int64_t last = -1;
    const absl::Status put = store->PutFile(d, path, [&](int64_t done, int64_t) { last = done; });
    ASSERT_TRUE(put.ok()) << put;
    EXPECT_EQ(last, static_cast<int64_t>(size));
    ASSERT_TRUE(store->PutFile(d, path).ok());  // already there: nothing sent
    const std::string out = temp.str() + "/out.bin";
    ASSERT_TRUE(store->GetFile(d, out).ok());
    std::ifstream in(out, std::ios::binary);
    EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), data);
  }
  EXPECT_EQ(store->GetFile(ComputeDigest("never stored"), temp.str() + "/x").code(),
            absl::StatusCode::kNotFound);
}

TEST_P(BlobStoreConformanceTest, ConcurrentPutsOfTheSameBlobsAgree) {
  auto store = Open();
  ASSERT_NE(store, nullptr);
  std::vector<std::string> blobs;
  for (int i = 0; i < 3; ++i) blobs.push_back(RandomBytes(20000 + i, 100 + i));
  std::vector<std::thread> threads;
  std::atomic<int> failures{0};
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&] {
      for (const std::string& b : blobs)
        if (!store->Put(ComputeDigest(b), b).ok()) ++failures;
    });
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(failures.load(), 0);
  for (const std::string& b : blobs) EXPECT_EQ(*store->Read(ComputeDigest(b)), b);
  EXPECT_EQ(store->Stats()->blob_count, 3);
}

}  // namespace instascene::store::testing

namespace instascene::store::testing {

TEST_P(BlobStoreConformanceTest, GrantsAreKeptPerTenant) {
  auto store = Open();
  ASSERT_NE(store, nullptr);
  const std::string data = RandomBytes(1000, 21);
  const Digest d = ComputeDigest(data);
  const Digest absent = ComputeDigest("never stored");
  ASSERT_TRUE(store->Put(d, data).ok());
  EXPECT_EQ(store->FindUngranted("acme", {d, absent})->size(), 2u);
  EXPECT_EQ(store->Grant("acme", {absent}).code(), absl::StatusCode::kFailedPrecondition);
  ASSERT_TRUE(store->Grant("acme", {d}).ok());
  ASSERT_TRUE(store->Grant("acme", {d}).ok());  // idempotent
  EXPECT_TRUE(store->FindUngranted("acme", {d})->empty());
  EXPECT_EQ(store->FindUngranted("beta", {d})->size(), 1u);
  EXPECT_EQ(store->Grant("../x", {d}).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(store->FindUngranted("Acme", {d}).status().code(), absl::StatusCode::kInvalidArgument);
  store.reset();
  store = Open();  // grants are durable
  ASSERT_NE(store, nullptr);
  EXPECT_TRUE(store->FindUngranted("acme", {d})->empty());
}

TEST_P(BlobStoreConformanceTest, TenantUploadsRevealNothingAndProvePossession) {
  if (!backend_->tenant_uploads()) GTEST_SKIP() << "no tenant uploads on this backend";
  const std::string data = RandomBytes(3 * kMiB + 5, 22);
  const Digest d = ComputeDigest(data);
  const int64_t half = int64_t{3} << 19;
  {
    auto store = Open();
    ASSERT_NE(store, nullptr);
    EXPECT_EQ(*store->TenantCommittedSize("acme", d), 0);
    ASSERT_EQ(*store->TenantAppend("acme", d, 0, Slice(data, 0, half)), half);
    // Neither the shared upload nor another tenant sees acme's progress.
    EXPECT_EQ(*store->CommittedSize(d), 0);
    EXPECT_EQ(*store->TenantCommittedSize("beta", d), 0);
  }
  auto store = Open();  // resumable across a restart, like the shared upload
  ASSERT_NE(store, nullptr);
  int64_t at = *store->TenantCommittedSize("acme", d);
  EXPECT_LE(at, half);
  EXPECT_GE(at, half - backend_->resume_loss_bytes());
  ASSERT_TRUE(store->TenantAppend("acme", d, at, Slice(data, at, d.size_bytes - at)).ok());
  ASSERT_TRUE(store->TenantFinishUpload("acme", d).ok());
  EXPECT_TRUE(store->FindMissing({d})->empty());
  EXPECT_TRUE(store->FindUngranted("acme", {d})->empty());
  EXPECT_EQ(*store->TenantCommittedSize("acme", d), d.size_bytes);
  // Sending it again once granted stages nothing (no part left to expire).
  EXPECT_EQ(*store->TenantAppend("acme", d, 0, data), d.size_bytes);
  EXPECT_TRUE(store->TenantFinishUpload("acme", d).ok());
  // beta must send every byte of a blob the store already holds to be granted it.
  EXPECT_EQ(*store->TenantCommittedSize("beta", d), 0);
  std::string forged = data;
  forged[100] ^= 1;
  ASSERT_TRUE(store->TenantAppend("beta", d, 0, forged).ok());
  EXPECT_EQ(store->TenantFinishUpload("beta", d).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(store->FindUngranted("beta", {d})->size(), 1u);
  EXPECT_EQ(*store->TenantCommittedSize("beta", d), 0) << "a wrong upload is discarded";
  ASSERT_TRUE(store->TenantAppend("beta", d, 0, data).ok());
  EXPECT_EQ(store->TenantFinishUpload("beta", d).code(), absl::StatusCode::kOk);
  EXPECT_TRUE(store->FindUngranted("beta", {d})->empty());
  EXPECT_EQ(*store->Read(d), data);
  const StoreStats stats = *store->Stats();
  EXPECT_EQ(stats.partial_uploads, 0) << "finished tenant uploads leave no part behind";
}

}  // namespace instascene::store::testing
