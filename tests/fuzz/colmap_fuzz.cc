// libFuzzer harness: the COLMAP model importer (text and binary) on arbitrary bytes. The first
// byte picks the format; the rest is split at the first "\n#--\n" (text) or the first 4 bytes
// read as a little-endian length (binary) into cameras and images. The importer reads a folder,
// so each input is written to one private folder (removed at exit).
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "common/scene/importers.h"

namespace {

struct Folder {
  std::string path;
  Folder() {
    std::string pattern = (std::filesystem::temp_directory_path() / "colmap_fuzz_XXXXXX").string();
    if (mkdtemp(pattern.data()) == nullptr) std::abort();
    path = pattern;
  }
  ~Folder() {
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
  }
};

void Write(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static Folder folder;
  if (size < 1) return 0;
  const bool binary = data[0] & 1;
  const std::string rest(reinterpret_cast<const char*>(data + 1), size - 1);
  std::string cameras, images;
  if (binary) {
    uint32_t n = 0;
    if (rest.size() >= 4) std::memcpy(&n, rest.data(), 4);
    const std::string body = rest.size() >= 4 ? rest.substr(4) : std::string();
    cameras = body.substr(0, std::min<size_t>(n, body.size()));
    images = body.substr(cameras.size());
  } else {
    const size_t cut = rest.find("\n#--\n");
    cameras = rest.substr(0, cut);
    images = cut == std::string::npos ? std::string() : rest.substr(cut + 5);
  }
  std::error_code ec;
  for (const char* name : {"cameras.bin", "images.bin", "cameras.txt", "images.txt"})
    std::filesystem::remove(folder.path + "/" + name, ec);
  Write(folder.path + (binary ? "/cameras.bin" : "/cameras.txt"), cameras);
  Write(folder.path + (binary ? "/images.bin" : "/images.txt"), images);
  (void)instascene::ImportColmapModel(folder.path);
  return 0;
}
