#include <gtest/gtest.h>

#include "common/rpc/credentials.h"
#include "common/rpc/status.h"

namespace instascene::rpc {
namespace {

TEST(ScrubPaths, AbsolutePathsLoseTheirFoldersOnly) {
  EXPECT_EQ(ScrubPaths("/srv/data/work/decomposition/x1/images/v003.png: cannot open"),
            "<server>/v003.png: cannot open");
  EXPECT_EQ(ScrubPaths("store /var/lib/instascene/store: in use by another process"),
            "store <server>/store: in use by another process");
  EXPECT_EQ(ScrubPaths("file '/tmp/a b/c.ply' (and \"/x/y/\")"),
            "file '<server>/a b/c.ply' (and \"<server>/y\")");
  // Not paths: digests, relative paths, URLs, fractions, a lone slash.
  for (const char* kept : {"blob 0123abcd/42 is not in the store", "images/v003.png: bad header",
                           "grpc://host:50051 unreachable", "3/4 done", "a / b"})
    EXPECT_EQ(ScrubPaths(kept), kept);
  EXPECT_EQ(ToGrpcStatus(absl::NotFoundError("/a/b/c.json: no such file")).error_message(),
            "<server>/c.json: no such file");
}

TEST(Credentials, HalfGivenTlsOptionsAreRefused) {
  TlsServerOptions server;
  server.cert_file = "cert.pem";
  EXPECT_EQ(MakeServerCredentials(server).status().code(), absl::StatusCode::kInvalidArgument);
  server = {};
  server.client_ca_file = "ca.pem";
  EXPECT_EQ(MakeServerCredentials(server).status().code(), absl::StatusCode::kInvalidArgument);
  server.cert_file = "/nonexistent/cert.pem";
  server.key_file = "/nonexistent/key.pem";
  EXPECT_EQ(MakeServerCredentials(server).status().code(), absl::StatusCode::kInvalidArgument);
  ChannelOptions channel;
  channel.tls_cert_file = "client.pem";
  EXPECT_FALSE(ValidateChannelOptions(channel).ok()) << "a client certificate without TLS";
  channel.tls_ca_file = "ca.pem";
  EXPECT_FALSE(ValidateChannelOptions(channel).ok()) << "a certificate without its key";
  channel.tls_key_file = "client.key";
  EXPECT_TRUE(ValidateChannelOptions(channel).ok());
  EXPECT_TRUE(MakeServerCredentials({}).ok()) << "plaintext";
}

}  // namespace
}  // namespace instascene::rpc
