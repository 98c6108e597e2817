// Garbage collection of the S3 store against a real S3-compatible server (moto, started here):
// what jobs reach stays, unreachable blobs past the grace period go with every tenant's grant, a
// grant whose blob is gone goes once old, a dry run removes nothing, and a presence check touches a
// blob written long ago (S3's self-copy with its metadata replaced) but not a recent one. The queue
// is SQLite here; the scale-out pairing with PostgreSQL and running services is
// tests/cluster_test.sh.
#include <gtest/gtest.h>

#include "common/store/s3_blob_store.h"
#include "common/store/testing/s3_server.h"
#include "services/store/garbage_collection.h"
#include "services/store/testing/gc_fixture.h"

namespace instascene::store_service {
namespace {

using store::testing::SharedS3Server;

class S3GarbageCollectionTest : public testing::GcFixture {
 protected:
  void SetUp() override {
    static int counter = 0;
    prefix_ = "gc" + std::to_string(++counter);
    store_ = OpenStore({});
    ASSERT_NE(store_, nullptr);
    OpenQueue();
  }
  store::BlobStore& blobs() override { return *store_; }
  std::unique_ptr<store::S3BlobStore> OpenStore(const store::S3StoreOptions& options) {
    auto s = store::S3BlobStore::Open(SharedS3Server().Location(prefix_),
                                      SharedS3Server().credentials(), {}, options);
    EXPECT_TRUE(s.ok()) << s.status();
    return s.ok() ? std::move(*s) : nullptr;
  }
  bool Exists(const std::string& key) {
    auto size = store_->client().HeadObject(key);
    EXPECT_TRUE(size.ok()) << size.status();
    return size.ok() && size->has_value();
  }
  bool Has(const store::Digest& d) { return Exists(store_->BlobKey(d)); }
  // A collection as if it ran `hours` from now (S3 sets modification times itself).
  absl::StatusOr<GcReport> Collect(int hours, bool dry_run = false) {
    GcOptions o;
    o.grace = std::chrono::hours(1);
    o.now = std::chrono::system_clock::now() + std::chrono::hours(hours);
    o.dry_run = dry_run;
    return CollectGarbage(*store_, *queue_, o);
  }

  std::string prefix_;
  std::unique_ptr<store::S3BlobStore> store_;
};

TEST_F(S3GarbageCollectionTest, WhatJobsReachStaysAndOldUnreachableBlobsGoWithTheirGrants) {
  const store::Digest scene = StoredManifest("scene", {{"scene.json", "{}"}, {"g.ply", "splat"}});
  const store::Digest output = StoredManifest("decompose", {{"labels.ply", "labels"}});
  SucceededJob("s", scene, output);
  const store::Digest orphan = Blob("orphan");
  ASSERT_TRUE(store_->Grant("acme", {orphan}).ok());
  ASSERT_TRUE(store_->Grant("beta", {orphan}).ok());
  const store::Digest kept_grant = store::ComputeDigest("labels");
  ASSERT_TRUE(store_->Grant("acme", {kept_grant}).ok());
  const store::Digest stray = StoredManifest("scene", {{"x", "stray file"}});

  // Now, everything is inside the grace period.
  absl::StatusOr<GcReport> young = Collect(0);
  ASSERT_TRUE(young.ok()) << young.status();
  EXPECT_EQ(young->blobs, 8);
  EXPECT_EQ(young->live_blobs, 5);
  EXPECT_EQ(young->young_blobs, 3);
  EXPECT_EQ(young->removed_blobs, 0);
  // Two hours on: a dry run counts, then the collection removes the three unreachable blobs.
  absl::StatusOr<GcReport> counted = Collect(2, /*dry_run=*/true);
  ASSERT_TRUE(counted.ok()) << counted.status();
  EXPECT_EQ(counted->removed_blobs, 3);
  EXPECT_TRUE(Has(orphan) && Has(stray));
  absl::StatusOr<GcReport> done = Collect(2);
  ASSERT_TRUE(done.ok()) << done.status();
  EXPECT_EQ(done->removed_blobs, 3);
  EXPECT_EQ(done->raced_blobs, 0);
  EXPECT_EQ(done->grants, 3);
  EXPECT_EQ(done->removed_grants, 2);  // the orphan's two, not the live blob's
  EXPECT_EQ(done->removed_bytes,
            orphan.size_bytes + stray.size_bytes + store::ComputeDigest("stray file").size_bytes);
  EXPECT_FALSE(Has(orphan) || Has(stray) || Has(store::ComputeDigest("stray file")));
  EXPECT_FALSE(Exists(store_->GrantKey("acme", orphan)));
  EXPECT_FALSE(Exists(store_->GrantKey("beta", orphan)));
  EXPECT_TRUE(Exists(store_->GrantKey("acme", kept_grant)));  // a live blob's grant stays
  for (const auto& d :
       {scene, output, kept_grant, store::ComputeDigest("splat"), store::ComputeDigest("{}")}) {
    EXPECT_TRUE(Has(d)) << d.ToString();
  }
  EXPECT_TRUE(store::ReadManifest(*store_, output).ok());
  EXPECT_EQ(Collect(2)->removed_blobs, 0);
}

// A grant whose blob is gone (written while a collector removed the blob): kept while young (it
// may be of a blob written since the listing), removed once past the grace period.
TEST_F(S3GarbageCollectionTest, AGrantWhoseBlobIsGoneGoesOnceOld) {
  const store::Digest gone = Blob("gone");
  ASSERT_TRUE(store_->Grant("acme", {gone}).ok());
  ASSERT_TRUE(store_->Remove(gone).ok());  // the blob only
  ASSERT_TRUE(Exists(store_->GrantKey("acme", gone)));
  absl::StatusOr<GcReport> young = Collect(0);
  ASSERT_TRUE(young.ok()) << young.status();
  EXPECT_EQ(young->grants, 1);
  EXPECT_EQ(young->removed_grants, 0);
  EXPECT_EQ(Collect(2, /*dry_run=*/true)->removed_grants, 1);
  EXPECT_TRUE(Exists(store_->GrantKey("acme", gone)));
  EXPECT_EQ(Collect(2)->removed_grants, 1);
  EXPECT_FALSE(Exists(store_->GrantKey("acme", gone)));
  EXPECT_EQ(*store_->TenantBytes("acme"), 0);
}

TEST_F(S3GarbageCollectionTest, APresenceCheckTouchesABlobWrittenLongAgo) {
  // A blob written with a metadata mark: a touch (self-copy, metadata replaced) drops the mark,
  // which S3 reports on HEAD, so the test sees the touch without waiting for the clock.
  const std::string bytes = "referenced again";
  const store::Digest d = store::ComputeDigest(bytes);
  store::S3Request put;
  put.method = "PUT";
  put.key = store_->BlobKey(d);
  put.body = bytes;
  put.headers = {"x-amz-meta-mark: 1"};
  auto sent = store_->client().Send(put);
  ASSERT_TRUE(sent.ok() && sent->status == 200) << sent.status();
  auto marked = [&] {
    store::S3Request head;
    head.method = "HEAD";
    head.key = store_->BlobKey(d);
    auto r = store_->client().Send(head);
    EXPECT_TRUE(r.ok()) << r.status();
    return r.ok() && r->headers.count("x-amz-meta-mark") > 0;
  };
  // Written less than the touch interval (1 h) ago: a presence check leaves it as it is.
  ASSERT_TRUE(store_->FindMissing({d}).ok());
  EXPECT_TRUE(marked());
  // With no interval, the blob counts as written long ago: FindMissing touches it, and the
  // bytes are intact.
  store::S3StoreOptions eager;
  eager.touch_after_seconds = 0;
  std::unique_ptr<store::S3BlobStore> touching = OpenStore(eager);
  ASSERT_NE(touching, nullptr);
  absl::StatusOr<std::vector<store::Digest>> missing = touching->FindMissing({d});
  ASSERT_TRUE(missing.ok()) << missing.status();
  EXPECT_TRUE(missing->empty());
  EXPECT_FALSE(marked());
  EXPECT_EQ(*touching->Read(d), bytes);
  // Its modification time, read again before a removal, is not older than the listing's.
  auto listed = touching->ListBlobs();
  ASSERT_TRUE(listed.ok() && listed->size() == 1);
  auto modified = touching->BlobModified(d);
  ASSERT_TRUE(modified.ok() && modified->has_value());
  EXPECT_GE(**modified, (*listed)[0].modified - std::chrono::seconds(1));
  EXPECT_FALSE(touching->BlobModified(store::ComputeDigest("never stored"))->has_value());
}

}  // namespace
}  // namespace instascene::store_service
