#include "common/core/file_io.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/core/json_file.h"
#include "common/core/testing/temp_dir.h"

namespace instascene {
namespace {

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(FileIo, WriteFileAtomicallyReplacesAndLeavesNoTemporary) {
  testing::ScopedTempDir dir("file_io");
  const std::string path = dir.Sub("a.bin");
  ASSERT_TRUE(WriteFileAtomically(path, "first").ok());
  ASSERT_TRUE(WriteFileAtomically(path, std::string("sec\0ond", 7)).ok());
  EXPECT_EQ(Slurp(path), std::string("sec\0ond", 7));
  size_t entries = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir.path())) ++entries;
  EXPECT_EQ(entries, 1u);
}

TEST(FileIo, FailedWriteLeavesTheOldFile) {
  testing::ScopedTempDir dir("file_io");
  const std::string path = dir.Sub("missing-folder/a.bin");
  const absl::Status s = WriteFileAtomically(path, "x");
  EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(s.message().find("missing-folder/a.bin"), std::string::npos) << s;
  // A path that is a directory cannot be replaced; its content stays.
  std::filesystem::create_directories(dir.Sub("d"));
  EXPECT_FALSE(WriteFileAtomically(dir.Sub("d"), "x").ok());
  EXPECT_TRUE(std::filesystem::is_directory(dir.Sub("d")));
  size_t entries = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir.path())) ++entries;
  EXPECT_EQ(entries, 1u);  // only d/: no temporary left
}

TEST(FileIo, ScopedTempDirRemovesItself) {
  std::filesystem::path kept;
  {
    testing::ScopedTempDir dir("scoped");
    kept = dir.path();
    std::ofstream(dir.Sub("f")) << "x";
    EXPECT_TRUE(std::filesystem::exists(dir.Sub("f")));
  }
  EXPECT_FALSE(std::filesystem::exists(kept));
}

TEST(JsonFile, ParsesOrSaysWhichFileIsNotJson) {
  testing::ScopedTempDir dir("json_file");
  ASSERT_TRUE(WriteFileAtomically(dir.Sub("good.json"), R"({"a": [1, 2]})").ok());
  ASSERT_TRUE(WriteFileAtomically(dir.Sub("bad.json"), "{\"a\": ").ok());
  const absl::StatusOr<nlohmann::json> good = ReadJsonFile(dir.Sub("good.json"), 1024);
  ASSERT_TRUE(good.ok()) << good.status();
  EXPECT_EQ((*good)["a"][1], 2);
  const absl::StatusOr<nlohmann::json> bad = ReadJsonFile(dir.Sub("bad.json"), 1024);
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(bad.status().message().find("bad.json: not JSON"), std::string::npos) << bad.status();
  EXPECT_EQ(ReadJsonFile(dir.Sub("missing.json"), 1024).status().code(),
            absl::StatusCode::kNotFound);
  EXPECT_EQ(ReadJsonFile(dir.Sub("good.json"), 4).status().code(),
            absl::StatusCode::kResourceExhausted);
}

}  // namespace
}  // namespace instascene
