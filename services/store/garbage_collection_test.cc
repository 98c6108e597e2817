// Garbage collection against a real filesystem store and SQLite queue: what jobs reach stays,
// unreachable blobs go once past the grace period (with their grants), young ones stay, grants
// whose blob is gone go once old, a dry run removes nothing, a damaged root stops the collection
// before any removal.
#include "services/store/garbage_collection.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "services/store/testing/gc_fixture.h"

namespace instascene::store_service {
namespace {

namespace fs = std::filesystem;

class GarbageCollectionTest : public testing::GcFixture {
 protected:
  void SetUp() override {
    auto blobs = store::FilesystemBlobStore::Open(temp_.Sub("store"), {});
    ASSERT_TRUE(blobs.ok()) << blobs.status();
    store_ = std::move(*blobs);
    OpenQueue();
  }
  store::BlobStore& blobs() override { return *store_; }

  void MakeOld(const store::Digest& d) {
    fs::last_write_time(store_->BlobPath(d),
                        fs::file_time_type::clock::now() - std::chrono::hours(48));
  }
  bool Has(const store::Digest& d) { return fs::exists(store_->BlobPath(d)); }

  std::unique_ptr<store::FilesystemBlobStore> store_;
};

TEST_F(GarbageCollectionTest, WhatJobsReachStaysAndOldUnreachableBlobsGo) {
  const store::Digest scene = StoredManifest("scene", {{"scene.json", "{}"}, {"g.ply", "splat"}});
  const store::Digest output = StoredManifest("decompose", {{"labels.ply", "labels"}});
  SucceededJob("s", scene, output);
  // A job naming a manifest the store does not hold: it reaches nothing, and is counted.
  ASSERT_TRUE(queue_->Submit(Request("t", store::ComputeDigest("never stored"))).ok());
  // Unreachable: an old orphan (granted to a tenant), a young one (an upload not yet submitted),
  // and an old manifest no job names, with its file.
  const store::Digest old_orphan = Blob("old orphan");
  ASSERT_TRUE(store_->Grant("acme", {old_orphan}).ok());
  const store::Digest young_orphan = Blob("young orphan");
  const store::Digest stray = StoredManifest("scene", {{"x", "stray file"}});
  const store::Digest stray_file = store::ComputeDigest("stray file");
  for (const auto& d : {scene, output, old_orphan, stray, stray_file}) MakeOld(d);
  MakeOld(store::ComputeDigest("labels"));
  MakeOld(store::ComputeDigest("splat"));

  GcOptions dry;
  dry.dry_run = true;
  absl::StatusOr<GcReport> counted = CollectGarbage(*store_, *queue_, dry);
  ASSERT_TRUE(counted.ok()) << counted.status();
  EXPECT_EQ(counted->jobs, 2);
  EXPECT_EQ(counted->missing_manifests, 1);
  EXPECT_EQ(counted->blobs, 9);
  EXPECT_EQ(counted->live_blobs, 5);  // two manifests and their three files
  EXPECT_EQ(counted->young_blobs, 1);
  EXPECT_EQ(counted->removed_blobs, 3);
  EXPECT_TRUE(Has(old_orphan) && Has(stray) && Has(stray_file));  // a dry run removes nothing

  absl::StatusOr<GcReport> done = CollectGarbage(*store_, *queue_, {});
  ASSERT_TRUE(done.ok()) << done.status();
  EXPECT_EQ(done->removed_blobs, 3);
  EXPECT_EQ(done->removed_grants, 1);  // the old orphan's
  EXPECT_EQ(done->removed_bytes, old_orphan.size_bytes + stray.size_bytes + stray_file.size_bytes);
  EXPECT_FALSE(Has(old_orphan) || Has(stray) || Has(stray_file));
  EXPECT_TRUE(Has(young_orphan));
  for (const auto& d : {scene, output, store::ComputeDigest("labels"),
                        store::ComputeDigest("splat"), store::ComputeDigest("{}")}) {
    EXPECT_TRUE(Has(d)) << d.ToString();
  }
  // The removed blob's grant went with it (FilesystemBlobStore's layout); the live manifests
  // still read.
  const fs::path grants = fs::path(temp_.Sub("store")) / "grants" / "acme";
  EXPECT_FALSE(fs::exists(grants / old_orphan.hash.substr(0, 2) /
                          (old_orphan.hash + "-" + std::to_string(old_orphan.size_bytes))));
  EXPECT_TRUE(fs::exists(grants));  // the grant existed: the tenant's folder is there
  EXPECT_TRUE(store::ReadManifest(*store_, output).ok());
  // Collected again: nothing left to remove.
  EXPECT_EQ(CollectGarbage(*store_, *queue_, {})->removed_blobs, 0);
}

// Grants whose blob is gone (one written while a collector removed its blob): each goes once
// older than the grace period; a young one (perhaps of a blob written since the listing) and one
// whose blob came back stay.
TEST_F(GarbageCollectionTest, GrantsWhoseBlobIsGoneGoOnceOld) {
  const store::Digest gone = Blob("gone"), young = Blob("young grant"), back = Blob("back");
  ASSERT_TRUE(store_->Grant("acme", {gone, young, back}).ok());
  for (const auto& d : {gone, young, back}) ASSERT_TRUE(store_->Remove(d).ok());  // grants stay
  Blob("back");  // uploaded again: a young unreachable blob
  for (const auto& d : {gone, back}) {
    fs::last_write_time(fs::path(temp_.Sub("store")) / "grants" / "acme" / d.hash.substr(0, 2) /
                            (d.hash + "-" + std::to_string(d.size_bytes)),
                        fs::file_time_type::clock::now() - std::chrono::hours(48));
  }
  GcOptions dry;
  dry.dry_run = true;
  absl::StatusOr<GcReport> counted = CollectGarbage(*store_, *queue_, dry);
  ASSERT_TRUE(counted.ok()) << counted.status();
  EXPECT_EQ(counted->grants, 3);
  EXPECT_EQ(counted->removed_grants, 1);
  EXPECT_EQ(store_->ListGrants()->size(), 3u);
  absl::StatusOr<GcReport> done = CollectGarbage(*store_, *queue_, {});
  ASSERT_TRUE(done.ok()) << done.status();
  EXPECT_EQ(done->removed_blobs, 0);
  EXPECT_EQ(done->removed_grants, 1);
  auto grants = store_->ListGrants();
  ASSERT_TRUE(grants.ok() && grants->size() == 2u);
  for (const store::StoredGrant& g : *grants) EXPECT_NE(g.digest, gone);
  EXPECT_EQ(*store_->TenantBytes("acme"), young.size_bytes + back.size_bytes);
}

TEST_F(GarbageCollectionTest, ABlobFoundPresentIsYoungAgain) {
  const store::Digest d = Blob("uploaded long ago");
  MakeOld(d);
  // A client about to reference it asks whether the store has it: it does, and it stays.
  ASSERT_TRUE(store_->FindMissing({d}).ok());
  absl::StatusOr<GcReport> r = CollectGarbage(*store_, *queue_, {});
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->young_blobs, 1);
  EXPECT_TRUE(Has(d));
  // With no grace period it goes.
  GcOptions now;
  now.grace = std::chrono::seconds(0);
  EXPECT_EQ(CollectGarbage(*store_, *queue_, now)->removed_blobs, 1);
  EXPECT_FALSE(Has(d));
}

TEST_F(GarbageCollectionTest, ADamagedRootStopsTheCollectionBeforeAnyRemoval) {
  ASSERT_TRUE(queue_->Submit(Request("s", Blob("this is not a manifest"))).ok());
  const store::Digest orphan = Blob("orphan");
  MakeOld(orphan);
  absl::StatusOr<GcReport> r = CollectGarbage(*store_, *queue_, {});
  EXPECT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("nothing removed"), std::string::npos) << r.status();
  EXPECT_TRUE(Has(orphan));
  GcOptions bad;
  bad.grace = std::chrono::seconds(-1);
  EXPECT_EQ(CollectGarbage(*store_, *queue_, bad).status().code(),
            absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace instascene::store_service
