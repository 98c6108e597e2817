// The ContentStore service over loopback gRPC, driven through RemoteBlobStore and raw stubs.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "common/auth/tokens.h"
#include "common/core/status.h"
#include "common/core/testing/files.h"
#include "common/core/testing/temp_dir.h"
#include "common/rpc/server.h"
#include "common/rpc/status.h"
#include "common/store/manifest.h"
#include "common/store/testing/blob_store_conformance.h"
#include "services/store/remote_blob_store.h"
#include "services/store/store_service.h"

namespace instascene::store_service {
namespace {
namespace fs = std::filesystem;
using instascene::testing::CountFiles;
using instascene::testing::RandomBytes;

// The conformance suite through the service: a filesystem store behind the ContentStore service
// on loopback, driven by RemoteBlobStore. Reopening restarts both the service and the client.
class RemoteBackend : public store::testing::BlobStoreBackend {
 public:
  absl::StatusOr<std::unique_ptr<store::BlobStore>> Open(
      const store::StoreOptions& options) override {
    server_.reset();
    service_.reset();
    local_.reset();
    ASSIGN_OR_RETURN(local_, store::FilesystemBlobStore::Open(temp_.str(), options));
    service_ = std::make_unique<StoreService>(local_.get());
    rpc::ServerOptions server_options;
    server_options.listen = "127.0.0.1:0";
    server_options.max_message_bytes = static_cast<int>(options.max_batch_bytes + (1 << 20));
    ASSIGN_OR_RETURN(server_, rpc::Server::Start(server_options, {service_.get()},
                                                 {"instascene.v1.ContentStore"}));
    ASSIGN_OR_RETURN(std::unique_ptr<RemoteBlobStore> remote,
                     RemoteBlobStore::Connect(rpc::Connect(server_->address())));
    return std::unique_ptr<store::BlobStore>(std::move(remote));
  }
  bool tenant_uploads() const override { return false; }  // the service's backend has them

 private:
  instascene::testing::ScopedTempDir temp_{"remote_conformance"};
  std::unique_ptr<store::FilesystemBlobStore> local_;
  std::unique_ptr<StoreService> service_;
  std::unique_ptr<rpc::Server> server_;
};

using store::testing::BlobStoreConformanceTest;
INSTANTIATE_TEST_SUITE_P(Remote, BlobStoreConformanceTest,
                         ::testing::Values(store::testing::BlobStoreBackendFactory{
                             "remote", [] { return std::make_unique<RemoteBackend>(); }}),
                         store::testing::BackendName);

class StoreServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = temp_.str();
    store::StoreOptions options;
    options.max_blob_bytes = 8 << 20;
    options.max_batch_bytes = 64 << 10;
    local_ = std::move(*store::FilesystemBlobStore::Open(root_ + "/store", options));
    service_ = std::make_unique<StoreService>(local_.get());
    auto server =
        rpc::Server::Start({"127.0.0.1:0"}, {service_.get()}, {"instascene.v1.ContentStore"});
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = std::move(*server);
    channel_ = rpc::Connect(server_->address());
    auto remote = RemoteBlobStore::Connect(channel_);
    ASSERT_TRUE(remote.ok()) << remote.status();
    remote_ = std::move(*remote);
    stub_ = v1::ContentStore::NewStub(channel_);
  }

  testing::ScopedTempDir temp_{"store_service"};  // first member: removed last
  std::string root_;
  std::unique_ptr<store::FilesystemBlobStore> local_;
  std::unique_ptr<StoreService> service_;
  std::unique_ptr<rpc::Server> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<RemoteBlobStore> remote_;
  std::unique_ptr<v1::ContentStore::Stub> stub_;
};

TEST_F(StoreServiceTest, SmallAndLargeBlobsRoundTrip) {
  EXPECT_EQ(remote_->options().max_batch_bytes, 64 << 10);
  for (size_t size : {0, 100, 64 << 10, (64 << 10) + 1, 3 << 20}) {
    const std::string data = RandomBytes(size, size + 1);
    const store::Digest d = store::ComputeDigest(data);
    ASSERT_TRUE(remote_->Put(d, data).ok()) << size;
    EXPECT_TRUE(remote_->FindMissing({d})->empty());
    EXPECT_EQ(*remote_->Read(d), data);
    EXPECT_EQ(*local_->Read(d), data);
    if (size > 10) {
      EXPECT_EQ(*remote_->Read(d, 5, 5), data.substr(5, 5));
    }
  }
}

TEST_F(StoreServiceTest, CorruptOversizedAndUnknownAreRejectedLeavingNothing) {
  const std::string data = RandomBytes(1000, 9);
  store::Digest wrong = store::ComputeDigest(data);
  wrong.hash[3] = wrong.hash[3] == '0' ? '1' : '0';
  absl::Status s = remote_->Put(wrong, data);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("digest mismatch"), std::string::npos) << s;
  // The same through the streaming path (a large blob with one flipped byte).
  std::string big = RandomBytes(200 << 10, 10);
  const store::Digest big_digest = store::ComputeDigest(big);
  big[1000] ^= 1;
  s = remote_->Put(big_digest, big);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  // Over the blob limit: the client refuses before sending, and so does the server when a raw
  // stream announces such a blob.
  const std::string huge = RandomBytes((8 << 20) + 1, 11);
  s = remote_->Put(store::ComputeDigest(huge), huge);
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted) << s;
  {
    grpc::ClientContext context;
    v1::WriteResponse response;
    auto writer = stub_->Write(&context, &response);
    v1::WriteRequest first;
    rpc::ToProto(store::ComputeDigest(huge), first.mutable_digest());
    first.set_data(huge.substr(0, 1000));
    writer->Write(first);
    writer->WritesDone();
    const grpc::Status gs = writer->Finish();
    EXPECT_EQ(gs.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << gs.error_message();
    EXPECT_NE(gs.error_message().find("larger than the store's limit"), std::string::npos);
  }
  // Unknown digest.
  const auto unknown = remote_->Read(store::ComputeDigest("never stored"));
  EXPECT_EQ(unknown.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(unknown.status().message().find("not in the store"), std::string::npos);
  // Malformed digest.
  v1::FindMissingBlobsRequest request;
  request.add_digests()->set_hash("zz");
  v1::FindMissingBlobsResponse response;
  grpc::ClientContext context;
  const grpc::Status gs = stub_->FindMissingBlobs(&context, request, &response);
  EXPECT_EQ(gs.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(gs.error_message().find("digests[0]"), std::string::npos);
  EXPECT_EQ(CountFiles(root_ + "/store"), 0u);
}

TEST_F(StoreServiceTest, InterruptedUploadResumesAtTheCommittedSize) {
  const std::string data = RandomBytes(3 << 20, 12);
  const store::Digest d = store::ComputeDigest(data);
  // The client "crashes" after 1 MiB + 7 bytes.
  ASSERT_TRUE(remote_->Append(d, 0, absl::string_view(data).substr(0, (1 << 20) + 7)).ok());
  EXPECT_EQ(*remote_->CommittedSize(d), (1 << 20) + 7);
  // A write at the wrong offset says where to resume.
  const auto wrong = remote_->Append(d, 0, "abc");
  EXPECT_EQ(wrong.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(wrong.status().message().find("1048583 bytes committed"), std::string::npos);
  const std::string path = root_ + "/upload.bin";
  std::ofstream(path, std::ios::binary) << data;
  int64_t first_progress = -1;
  ASSERT_TRUE(remote_
                  ->PutFile(d, path,
                            [&](int64_t done, int64_t) {
                              if (first_progress < 0) first_progress = done;
                            })
                  .ok());
  EXPECT_GT(first_progress, (1 << 20) + 7);  // continued, did not start over
  EXPECT_EQ(*local_->Read(d), data);
}

TEST_F(StoreServiceTest, ManifestUploadThroughTheServiceSendsOnlyMissingFiles) {
  const std::string dir = root_ + "/result";
  fs::create_directories(dir + "/instances");
  std::ofstream(dir + "/a.txt") << "alpha";
  std::ofstream(dir + "/instances/1.ply") << RandomBytes(100 << 10, 13);
  auto manifest = store::ManifestFromDirectory(dir, "segment");
  ASSERT_TRUE(manifest.ok());
  auto first = store::UploadManifest(*remote_, *manifest, dir);
  ASSERT_TRUE(first.ok()) << first.status();
  EXPECT_EQ(first->files_sent, 2);
  auto second = store::UploadManifest(*remote_, *manifest, dir);
  EXPECT_EQ(second->files_sent, 0);
  auto back = store::ReadManifest(*remote_, first->manifest);
  ASSERT_TRUE(back.ok());
  ASSERT_TRUE(store::MaterializeManifest(*remote_, *back, root_ + "/copy").ok());
  std::ifstream in(root_ + "/copy/a.txt");
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), "alpha");
}

}  // namespace

// Tenants through the service: each client token sees only what its tenant uploaded or was granted.
TEST(StoreServiceAuth, TenantsSeeOnlyTheirBlobsAndRolesAreEnforced) {
  instascene::testing::ScopedTempDir temp("store_auth");
  const std::string tokens = temp.Sub("tokens.json");
  const std::string acme = *auth::CreateToken(tokens, auth::Role::kClient, "acme", "");
  const std::string beta = *auth::CreateToken(tokens, auth::Role::kClient, "beta", "");
  const std::string worker = *auth::CreateToken(tokens, auth::Role::kWorker, "", "");
  std::shared_ptr<auth::Authenticator> authenticator = *auth::Authenticator::FromFile(tokens);
  store::StoreOptions options;
  options.max_batch_bytes = 64 << 10;  // larger blobs take the Write stream
  auto local = *store::FilesystemBlobStore::Open(temp.Sub("store"), options);
  StoreService service(local.get(), authenticator.get());
  rpc::ServerOptions server_options;
  server_options.listen = "127.0.0.1:0";
  auto server = *rpc::Server::Start(server_options, {&service}, {"instascene.v1.ContentStore"});
  auto connect = [&](const std::string& token) {
    rpc::ChannelOptions channel;
    channel.token = token;
    return RemoteBlobStore::Connect(*rpc::Connect(server->address(), channel));
  };
  EXPECT_EQ(connect("").status().code(), absl::StatusCode::kUnauthenticated);
  auto a = *connect(acme);
  auto b = *connect(beta);
  auto w = *connect(worker);
  const std::string small = RandomBytes(1000, 31), large = RandomBytes(300 << 10, 32);
  const store::Digest ds = store::ComputeDigest(small), dl = store::ComputeDigest(large);
  ASSERT_TRUE(a->Put(ds, small).ok());
  ASSERT_TRUE(a->Put(dl, large).ok());
  EXPECT_TRUE(a->FindMissing({ds, dl})->empty());
  EXPECT_EQ(*a->Read(dl), large);
  // beta learns nothing: both blobs are missing to it, reads are NOT_FOUND like unknown blobs.
  EXPECT_EQ(b->FindMissing({ds, dl})->size(), 2u);
  EXPECT_EQ(b->Read(ds).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(*b->CommittedSize(dl), 0);
  EXPECT_EQ(b->Stats()->blob_count, 0) << "store statistics are for workers and admins";
  EXPECT_EQ(w->Stats()->blob_count, 2);
  // beta uploads the same large blob in full and is granted it; the store keeps one copy.
  ASSERT_TRUE(b->Put(dl, large).ok());
  EXPECT_EQ(*b->Read(dl), large);
  EXPECT_EQ(b->FindMissing({ds})->size(), 1u);
  EXPECT_EQ(w->Stats()->blob_count, 2);
  // Workers read everything and grant; clients may not grant.
  EXPECT_EQ(*w->Read(ds), small);
  EXPECT_EQ(b->Grant("beta", {ds}).code(), absl::StatusCode::kPermissionDenied);
  ASSERT_TRUE(w->Grant("beta", {ds}).ok());
  EXPECT_EQ(*b->Read(ds), small);
  EXPECT_TRUE(w->FindUngranted("beta", {ds, dl})->empty());
  EXPECT_EQ(w->Grant("beta", {store::ComputeDigest("absent")}).code(),
            absl::StatusCode::kFailedPrecondition);
}

}  // namespace instascene::store_service
