// The S3 backend against a real S3-compatible server (moto, started here with SigV4 checking on):
// the blob-store conformance suite plus what only S3 has (URIs, credentials, signatures,
// addressing styles, multipart resume and copy, verification before publication).
#include <gtest/gtest.h>
#include <stdlib.h>

#include <fstream>
#include <thread>

#include <httplib.h>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "common/core/status.h"
#include "common/core/testing/files.h"
#include "common/core/testing/temp_dir.h"
#include "common/store/blob_store_uri.h"
#include "common/store/s3_blob_store.h"
#include "common/store/testing/blob_store_conformance.h"
#include "common/store/testing/s3_server.h"

namespace instascene::store {
namespace {
using instascene::testing::RandomBytes;
using store::testing::BlobStoreConformanceTest;
using store::testing::S3Server;
using store::testing::SharedS3Server;
constexpr int64_t kMiB = int64_t{1} << 20;

std::string UniquePrefix() {
  static int counter = 0;
  return absl::StrCat("t", ++counter);
}

S3StoreOptions SmallParts() {
  S3StoreOptions o;
  o.part_bytes = 5 * kMiB;  // S3's minimum, so that the tests' blobs span several parts
  o.copy_part_bytes = 5 * kMiB;
  return o;
}

class S3Backend : public store::testing::BlobStoreBackend {
 public:
  absl::StatusOr<std::unique_ptr<BlobStore>> Open(const StoreOptions& options) override {
    ASSIGN_OR_RETURN(std::unique_ptr<S3BlobStore> store,
                     S3BlobStore::Open(SharedS3Server().Location(prefix_),
                                       SharedS3Server().credentials(), options, SmallParts()));
    return std::unique_ptr<BlobStore>(std::move(store));
  }
  int64_t resume_loss_bytes() const override { return 5 * kMiB - 1; }

 private:
  const std::string prefix_ = UniquePrefix();
};

INSTANTIATE_TEST_SUITE_P(S3, BlobStoreConformanceTest,
                         ::testing::Values(store::testing::BlobStoreBackendFactory{
                             "s3", [] { return std::make_unique<S3Backend>(); }}),
                         store::testing::BackendName);

std::unique_ptr<S3BlobStore> OpenS3(const std::string& prefix, S3StoreOptions s3 = SmallParts(),
                                    S3ClientOptions client = {}) {
  auto store = S3BlobStore::Open(SharedS3Server().Location(prefix), SharedS3Server().credentials(),
                                 StoreOptions{}, s3, client);
  EXPECT_TRUE(store.ok()) << store.status();
  return store.ok() ? std::move(*store) : nullptr;
}

TEST(S3LocationTest, ParsesAndRefuses) {
  auto loc = S3Location::Parse(
      "s3://my-bucket/scenes/site1/?endpoint=http://minio:9000/&region=eu-west-1");
  ASSERT_TRUE(loc.ok()) << loc.status();
  EXPECT_EQ(loc->bucket, "my-bucket");
  EXPECT_EQ(loc->prefix, "scenes/site1/");
  EXPECT_EQ(loc->endpoint, "http://minio:9000");
  EXPECT_EQ(loc->region, "eu-west-1");
  EXPECT_TRUE(loc->path_style);
  EXPECT_EQ(loc->Url("scenes/site1/cas/ab"), "http://minio:9000/my-bucket/scenes/site1/cas/ab");
  EXPECT_EQ(S3Location::Parse(loc->ToString())->ToString(), loc->ToString());
  // AWS by default: the regional endpoint, virtual-hosted.
  loc = S3Location::Parse("s3://my-bucket?region=us-west-2");
  ASSERT_TRUE(loc.ok());
  EXPECT_EQ(loc->prefix, "");
  EXPECT_FALSE(loc->path_style);
  EXPECT_EQ(loc->Url("cas/ab"), "https://my-bucket.s3.us-west-2.amazonaws.com/cas/ab");
  EXPECT_EQ(loc->Url(""), "https://my-bucket.s3.us-west-2.amazonaws.com/");
  loc = S3Location::Parse("s3://b12/p?endpoint=https://rgw.example:7480&addressing=virtual");
  ASSERT_TRUE(loc.ok());
  EXPECT_EQ(loc->Url("p/x"), "https://b12.rgw.example:7480/p/x");
  for (const char* bad :
       {"s3:/b12", "http://b12", "s3://B12", "s3://ab", "s3://b12/a//b", "s3://b12/../x",
        "s3://b12/a b", "s3://b12?endpoint=ftp://x", "s3://b12?endpoint=http://x/path",
        "s3://b12?secret=x", "s3://b12?addressing=dns", "s3://b12?region=US"}) {
    const auto parsed = S3Location::Parse(bad);
    EXPECT_EQ(parsed.status().code(), absl::StatusCode::kInvalidArgument) << bad;
  }
}

TEST(S3LocationTest, UriEncodingFollowsSigV4) {
  EXPECT_EQ(AwsUriEncode("a-b_c.d~e/f g+h=", false), "a-b_c.d~e%2Ff%20g%2Bh%3D");
  EXPECT_EQ(AwsUriEncode("a/b", true), "a/b");
}

TEST(S3SignatureTest, MatchesAwsPublishedExample) {
  // The "GET Object" example of AWS's SigV4 documentation for S3 (Authenticating Requests:
  // Using the Authorization Header), with its published signature.
  const S3Credentials c{"AKIAIOSFODNN7EXAMPLE", "wJalrXUtnFEMI/K7MDENG/bPxRfiCYEXAMPLEKEY", ""};
  const std::map<std::string, std::string> headers = {
      {"host", "examplebucket.s3.amazonaws.com"},
      {"range", "bytes=0-9"},
      {"x-amz-content-sha256", "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"},
      {"x-amz-date", "20130524T000000Z"}};
  EXPECT_EQ(SignS3RequestV4("GET", "/test.txt", "", headers, "us-east-1", c),
            "AWS4-HMAC-SHA256 Credential=AKIAIOSFODNN7EXAMPLE/20130524/us-east-1/s3/aws4_request, "
            "SignedHeaders=host;range;x-amz-content-sha256;x-amz-date, "
            "Signature=f0e8bdb87c964420e857bd35b5d6ed310bd44f0170aba48dd91039c6036bdb41");
}

TEST(S3SignatureTest, CurlSignsWhatSigV4Specifies) {
  // A captured request (cpp-httplib on loopback): curl's built-in signature must equal the spec
  // signer's (which matches AWS's example above) for a listing whose prefix holds '/', sent as
  // %2F; and requests curl 7.88 would misorder are signed by the spec signer itself.
  httplib::Server capture;
  std::vector<std::pair<std::string, httplib::Headers>> seen;
  std::mutex mutex;
  const auto record = [&](const httplib::Request& req, httplib::Response& res) {
    std::lock_guard<std::mutex> lock(mutex);
    const size_t q = req.target.find('?');
    const std::string query = q == std::string::npos ? "" : req.target.substr(q + 1);
    seen.push_back({req.method + " " + req.path + "?" + query, req.headers});
    res.set_content("<ListBucketResult><IsTruncated>false</IsTruncated></ListBucketResult>",
                    "application/xml");
  };
  capture.Get(".*", record);
  capture.Put(".*", [&](const httplib::Request& req, httplib::Response& res) {
    record(req, res);
    res.set_content("<CopyPartResult><ETag>\"e\"</ETag></CopyPartResult>", "application/xml");
  });
  capture.set_keep_alive_max_count(1);  // no idle keep-alive connection to wait for at stop()
  const int port = capture.bind_to_any_port("127.0.0.1");
  std::thread serving([&] { capture.listen_after_bind(); });
  // (bind_to_any_port already listens: requests wait in the backlog until the loop runs.)
  S3Location loc;
  loc.endpoint = absl::StrCat("http://127.0.0.1:", port);
  loc.bucket = "spec-bucket";
  const S3Credentials c{"AKIDTEST", "secret/key+value", ""};
  S3Client client(loc, c);
  EXPECT_TRUE(client.ListObjects("scenes/site1/cas/").ok());
  EXPECT_TRUE(client.UploadPartCopy("dst", "up.1", 2, "src/a", 0, 9).ok());
  EXPECT_TRUE(client.PutObject("k", "abc").ok());
  capture.stop();
  serving.join();
  ASSERT_EQ(seen.size(), 3u);
  for (const auto& [line, headers] : seen) {
    const std::string target = line.substr(line.find(' ') + 1);
    const std::string path = target.substr(0, target.find('?'));
    const std::string query = target.substr(target.find('?') + 1);
    const std::string auth = headers.find("Authorization")->second;
    const std::string signed_list =
        auth.substr(auth.find("SignedHeaders=") + 14,
                    auth.find(", Signature") - auth.find("SignedHeaders=") - 14);
    std::map<std::string, std::string> signed_headers;
    for (absl::string_view name : absl::StrSplit(signed_list, ';')) {
      for (const auto& [k, v] : headers)
        if (absl::AsciiStrToLower(k) == name) signed_headers[std::string(name)] = v;
    }
    EXPECT_EQ(auth, SignS3RequestV4(line.substr(0, line.find(' ')), path, query, signed_headers,
                                    "us-east-1", c))
        << line;
  }
  EXPECT_EQ(seen[0].first, "GET /spec-bucket?list-type=2&prefix=scenes%2Fsite1%2Fcas%2F");
  // Uploads carry Content-MD5 (RFC 1864; MD5("abc") = 900150983cd24fb0d6963f7d28e17f72), checked by
  // S3 servers before storing (not by moto).
  EXPECT_EQ(seen[2].second.find("Content-MD5")->second, "kAFQmDzST7DWlj99KOF/cg==");
  EXPECT_NE(seen[1]
                .second.find("Authorization")
                ->second.find("x-amz-copy-source;x-amz-copy-source-range"),
            std::string::npos);
}

TEST(S3CredentialsTest, EnvironmentThenSharedFile) {
  const instascene::testing::ScopedTempDir temp("s3_credentials");
  const std::string file = temp.str() + "/credentials";
  std::ofstream(file) << "# comment\n[default]\naws_access_key_id = AKIDEFAULT\n"
                         "aws_secret_access_key=secretdefault\n\n[profile ci]\n"
                         "aws_access_key_id=AKICI\naws_secret_access_key = secretci\n"
                         "aws_session_token = tok\n[broken]\naws_access_key_id=x\n";
  ::unsetenv("AWS_ACCESS_KEY_ID");
  ::unsetenv("AWS_SECRET_ACCESS_KEY");
  ::setenv("AWS_SHARED_CREDENTIALS_FILE", file.c_str(), 1);
  auto c = S3Credentials::Load();
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->access_key_id, "AKIDEFAULT");
  EXPECT_EQ(c->secret_access_key, "secretdefault");
  ::setenv("AWS_PROFILE", "ci", 1);
  c = S3Credentials::Load();
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->access_key_id, "AKICI");
  EXPECT_EQ(c->session_token, "tok");
  ::setenv("AWS_PROFILE", "broken", 1);
  EXPECT_EQ(S3Credentials::Load().status().code(), absl::StatusCode::kFailedPrecondition);
  ::setenv("AWS_PROFILE", "absent", 1);
  EXPECT_NE(S3Credentials::Load().status().message().find("no profile [absent]"),
            std::string::npos);
  // The environment wins over the file; half of a key pair is an error.
  ::setenv("AWS_ACCESS_KEY_ID", "AKIENV", 1);
  EXPECT_EQ(S3Credentials::Load().status().code(), absl::StatusCode::kFailedPrecondition);
  ::setenv("AWS_SECRET_ACCESS_KEY", "secretenv", 1);
  c = S3Credentials::Load();
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(c->access_key_id, "AKIENV");
  ::unsetenv("AWS_ACCESS_KEY_ID");
  ::unsetenv("AWS_SECRET_ACCESS_KEY");
  ::unsetenv("AWS_PROFILE");
  ::setenv("AWS_SHARED_CREDENTIALS_FILE", (temp.str() + "/none").c_str(), 1);
  EXPECT_NE(S3Credentials::Load().status().message().find("no S3 credentials"), std::string::npos);
  ::unsetenv("AWS_SHARED_CREDENTIALS_FILE");
}

TEST(S3ClientTest, WrongSecretIsRefusedBySignatureCheckAndNeverEchoed) {
  S3Credentials wrong = SharedS3Server().credentials();
  wrong.secret_access_key = "not-the-secret-0123456789";
  auto store = S3BlobStore::Open(SharedS3Server().Location("wrong"), wrong, StoreOptions{});
  EXPECT_EQ(store.status().code(), absl::StatusCode::kPermissionDenied) << store.status();
  EXPECT_NE(store.status().message().find("SignatureDoesNotMatch"), std::string::npos)
      << store.status();
  EXPECT_EQ(store.status().message().find("not-the-secret"), std::string::npos);
  S3Location missing = SharedS3Server().Location("x");
  missing.bucket = "no-such-bucket";
  store = S3BlobStore::Open(missing, SharedS3Server().credentials(), StoreOptions{});
  EXPECT_EQ(store.status().code(), absl::StatusCode::kNotFound) << store.status();
}

TEST(S3ClientTest, UnreachableEndpointIsUnavailable) {
  S3Location nowhere = SharedS3Server().Location("x");
  nowhere.endpoint = "http://127.0.0.1:1";
  S3ClientOptions client;
  client.max_attempts = 2;
  client.initial_backoff_ms = 1;
  auto store =
      S3BlobStore::Open(nowhere, SharedS3Server().credentials(), StoreOptions{}, {}, client);
  EXPECT_EQ(store.status().code(), absl::StatusCode::kUnavailable) << store.status();
}

TEST(S3ClientTest, VirtualHostedAddressing) {
  // bucket.s3.test resolves to the local server, as bucket.s3.REGION.amazonaws.com would to AWS.
  const std::string port =
      SharedS3Server().endpoint().substr(SharedS3Server().endpoint().rfind(':') + 1);
  S3Location loc = SharedS3Server().Location("virtual");
  loc.endpoint = absl::StrCat("http://s3.test:", port);
  loc.path_style = false;
  S3ClientOptions client;
  client.resolve = {absl::StrCat(SharedS3Server().bucket(), ".s3.test:", port, ":127.0.0.1")};
  auto store =
      S3BlobStore::Open(loc, SharedS3Server().credentials(), StoreOptions{}, SmallParts(), client);
  ASSERT_TRUE(store.ok()) << store.status();
  const std::string data = RandomBytes(3000, 41);
  const Digest d = ComputeDigest(data);
  ASSERT_TRUE((*store)->Put(d, data).ok());
  EXPECT_EQ(*(*store)->Read(d, 100, 10), data.substr(100, 10));
  // The same object through path-style addressing.
  auto path = OpenS3("virtual");
  EXPECT_EQ(*path->Read(d), data);
}

TEST(S3BlobStoreTest, LargeBlobsUseMultipartUploadAndCopyAndClearTheirStaging) {
  auto store = OpenS3("multipart");
  ASSERT_NE(store, nullptr);
  const std::string data = RandomBytes(12 * kMiB + 123, 42);
  const Digest d = ComputeDigest(data);
  for (int64_t at = 0; at < d.size_bytes; at += 3 * kMiB)
    ASSERT_TRUE(store->Append(d, at, data.substr(at, 3 * kMiB)).ok());
  const absl::Status finished = store->FinishUpload(d);
  ASSERT_TRUE(finished.ok()) << finished;
  EXPECT_EQ(*store->Read(d, 11 * kMiB, 7), data.substr(11 * kMiB, 7));
  EXPECT_EQ(*store->Read(d), data);
  // Nothing is left under uploads/: no object, no open multipart upload.
  auto objects = store->client().ListObjects("multipart/");
  ASSERT_TRUE(objects.ok()) << objects.status();
  ASSERT_EQ(objects->size(), 1u);
  EXPECT_EQ((*objects)[0].key, store->BlobKey(d));
  EXPECT_TRUE(store->client().ListMultipartUploads("multipart/")->empty());
}

TEST(S3BlobStoreTest, ATenantsBytesAreTheSizesOfItsGrants) {
  auto store = OpenS3("tenant-bytes");
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(*store->TenantBytes("acme"), 0);
  const std::string a = "seven b", b = "eleven byte";
  for (const std::string* s : {&a, &b}) ASSERT_TRUE(store->Put(ComputeDigest(*s), *s).ok());
  ASSERT_TRUE(store->Grant("acme", {ComputeDigest(a), ComputeDigest(b)}).ok());
  ASSERT_TRUE(store->Grant("acme", {ComputeDigest(a)}).ok());
  ASSERT_TRUE(store->Grant("acme-2", {ComputeDigest(a)}).ok());  // a name extending acme's
  EXPECT_EQ(*store->TenantBytes("acme"), 18);
  EXPECT_EQ(*store->TenantBytes("acme-2"), 7);
  // A removed blob's grants stay until the collector removes them (garbage_collection.h).
  ASSERT_TRUE(store->Remove(ComputeDigest(b)).ok());
  auto grants = store->ListGrants();
  ASSERT_TRUE(grants.ok()) << grants.status();
  ASSERT_EQ(grants->size(), 3u);
  EXPECT_EQ((*grants)[0].tenant, "acme");
  EXPECT_EQ((*grants)[2].tenant, "acme-2");
  EXPECT_EQ((*grants)[2].digest, ComputeDigest(a));
  EXPECT_EQ(*store->TenantBytes("acme"), 18);
  ASSERT_TRUE(store->RemoveGrant("acme", ComputeDigest(b)).ok());
  ASSERT_TRUE(store->RemoveGrant("acme", ComputeDigest(b)).ok());  // absent: not an error
  EXPECT_EQ(*store->TenantBytes("acme"), 7);
  EXPECT_EQ(store->ListGrants()->size(), 2u);
}

TEST(S3BlobStoreTest, AnUploadCorruptedInStorageIsNeverPublished) {
  // A client's upload was assembled under uploads/, then its bytes changed before verification
  // (bit rot, a buggy proxy): finishing must verify and refuse it.
  auto store = OpenS3("corrupt");
  ASSERT_NE(store, nullptr);
  std::string data = RandomBytes(6 * kMiB, 43);
  const Digest d = ComputeDigest(data);
  data[5] ^= 1;
  ASSERT_TRUE(store->client().PutObject(store->UploadKey(d), data).ok());
  auto fresh = OpenS3("corrupt");
  EXPECT_EQ(*fresh->CommittedSize(d), d.size_bytes);  // assembled, awaiting verification
  const absl::Status s = fresh->FinishUpload(d);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
  EXPECT_FALSE(fresh->FindMissing({d})->empty());
  EXPECT_TRUE(fresh->client().ListObjects("corrupt/")->empty());
}

TEST(S3BlobStoreTest, BufferedBytesAreBoundedAndADroppedBufferIsResent) {
  S3StoreOptions s3 = SmallParts();
  s3.max_buffered_uploads = 1;
  auto store = OpenS3("buffers", s3);
  ASSERT_NE(store, nullptr);
  const std::string a = RandomBytes(2 * kMiB, 44), b = RandomBytes(2 * kMiB, 45);
  const Digest da = ComputeDigest(a), db = ComputeDigest(b);
  ASSERT_TRUE(store->Append(da, 0, a.substr(0, kMiB)).ok());
  ASSERT_TRUE(store->Append(db, 0, b.substr(0, kMiB)).ok());  // drops a's buffer
  const auto resumed = store->Append(da, kMiB, a.substr(kMiB));
  EXPECT_EQ(resumed.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(*store->CommittedSize(da), 0);
  ASSERT_TRUE(store->Append(da, 0, a).ok());
  ASSERT_TRUE(store->FinishUpload(da).ok());
  ASSERT_TRUE(store->Append(db, kMiB, b.substr(kMiB)).ok() || store->Append(db, 0, b).ok());
  ASSERT_TRUE(store->FinishUpload(db).ok());
  EXPECT_EQ(*store->Read(da), a);
  EXPECT_EQ(*store->Read(db), b);
}

TEST(S3BlobStoreTest, StoreUriOpensS3WithEnvironmentCredentials) {
  ::setenv("AWS_ACCESS_KEY_ID", SharedS3Server().credentials().access_key_id.c_str(), 1);
  ::setenv("AWS_SECRET_ACCESS_KEY", SharedS3Server().credentials().secret_access_key.c_str(), 1);
  const std::string uri =
      absl::StrCat("s3://", SharedS3Server().bucket(),
                   "/uri?endpoint=", SharedS3Server().endpoint(), "&query_slash=literal");
  auto store = OpenBlobStoreUri(uri, StoreOptions{});
  ::unsetenv("AWS_ACCESS_KEY_ID");
  ::unsetenv("AWS_SECRET_ACCESS_KEY");
  ASSERT_TRUE(store.ok()) << store.status();
  ASSERT_TRUE((*store)->Put(ComputeDigest("abc"), "abc").ok());
  EXPECT_EQ(OpenBlobStoreUri("gs://x", StoreOptions{}).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(IsBlobStoreUri("file:/x") && IsBlobStoreUri(uri) && !IsBlobStoreUri("host:1"));
}

}  // namespace
}  // namespace instascene::store
