// object_at_point: what a robot integrator starts from. Looks up the object nearest a 3D point of a
// scene on an InstaScene server, prints its pose, metric size and artefacts, and downloads them.
//
//   object_at_point SERVER SCENE X Y Z [OUT_DIR]
//   INSTASCENE_TOKEN_FILE=robot.token object_at_point 127.0.0.1:50051 kitchen 0.42 -0.10 0.78
//   /tmp/cup
// The bearer token (`instascene token create --tenant ...` makes one for a robot fleet) comes from
// the file named by $INSTASCENE_TOKEN_FILE, or $INSTASCENE_TOKEN itself.
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>

#include "instascene/client/client.h"

namespace {

// The server and the bearer token: $INSTASCENE_TOKEN_FILE (a file holding the token) or
// $INSTASCENE_TOKEN. False when the token file cannot be read.
bool OptionsFromEnvironment(const char* server, instascene::client::ClientOptions* options) {
  options->server = server;
  if (const char* token = std::getenv("INSTASCENE_TOKEN")) options->token = token;
  if (const char* file = std::getenv("INSTASCENE_TOKEN_FILE")) {
    std::ifstream in(file);
    if (!std::getline(in, options->token)) {
      std::fprintf(stderr, "cannot read a token from %s\n", file);
      return false;
    }
  }
  return true;
}

// What a robot stack needs of the object: its pose in the scene, its size, its artefacts.
void PrintObject(const instascene::client::ObjectInfo& o) {
  const auto& t = o.world_from_object.translation;
  std::printf("object %u of scene %s (%s, %s)\n", o.id, o.scene.c_str(), o.source.c_str(),
              o.completion.c_str());
  std::printf("  position   %.4f %.4f %.4f (%s)\n", t.x, t.y, t.z, o.units.c_str());
  std::printf("  rotation   %.4f %.4f %.4f %.4f (quaternion x y z w)\n", o.world_from_object.qx,
              o.world_from_object.qy, o.world_from_object.qz, o.world_from_object.qw);
  std::printf("  size       %.4f x %.4f x %.4f (%s)\n", o.extent.x, o.extent.y, o.extent.z,
              o.units.c_str());
  for (const auto& a : o.artefacts)
    std::printf("  artefact   %-22s %8lld bytes  %s\n", a.path.c_str(),
                static_cast<long long>(a.bytes), a.media_type.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 6 && argc != 7) {
    std::fprintf(stderr, "usage: %s SERVER SCENE X Y Z [OUT_DIR]\n", argv[0]);
    return 2;
  }
  using instascene::client::Client;
  using instascene::client::ObjectSelector;
  instascene::client::ClientOptions options;
  if (!OptionsFromEnvironment(argv[1], &options)) return 1;
  auto client = Client::Connect(options);
  if (!client.ok()) {
    std::fprintf(stderr, "connect: %s\n", client.status().ToString().c_str());
    return 1;
  }
  const instascene::client::Vec3 point{std::atof(argv[3]), std::atof(argv[4]), std::atof(argv[5])};
  auto object = (*client)->GetObject(argv[2], ObjectSelector::Point(point));
  if (!object.ok()) {  // NOT_FOUND: nothing near that point
    std::fprintf(stderr, "lookup: %s\n", object.status().ToString().c_str());
    return 1;
  }
  PrintObject(*object);
  if (argc == 7) {
    auto files = (*client)->DownloadObject(*object, argv[6]);
    if (!files.ok()) {
      std::fprintf(stderr, "download: %s\n", files.status().ToString().c_str());
      return 1;
    }
    std::printf("downloaded %lld files (%lld bytes, digests verified) into %s\n",
                static_cast<long long>(files->files), static_cast<long long>(files->bytes),
                argv[6]);
  }
  return 0;
}
