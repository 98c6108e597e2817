// The main of a test binary that needs an S3 server (s3_server.h): one moto server for all its
// tests, started before them and stopped when the binary exits.
#include <gtest/gtest.h>

#include <cstdio>

#include "common/store/testing/s3_server.h"

namespace instascene::store::testing {
namespace {
S3Server* shared_server = nullptr;
}  // namespace

S3Server& SharedS3Server() { return *shared_server; }

}  // namespace instascene::store::testing

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  auto server = instascene::store::testing::S3Server::Start();
  if (!server.ok()) {
    std::fprintf(stderr, "FAIL: %s\n", server.status().ToString().c_str());
    return 1;
  }
  instascene::store::testing::shared_server = server->get();
  return RUN_ALL_TESTS();
}
