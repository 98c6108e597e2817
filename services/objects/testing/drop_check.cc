// objects_drop_check: the MuJoCo drop of exported objects (tests/export_test.sh). Usage:
//   objects_drop_check object.xml...   one line per object; exits 1 if any is not at rest after a
//   simulated second, exploded, tunnelled below the floor, or did not load.
#include <cstdio>

#include "services/objects/testing/mujoco_drop.h"

int main(int argc, char** argv) {
  int failed = 0;
  for (int i = 1; i < argc; ++i) {
    auto r = instascene::objects::testing::DropOntoFloor(argv[i]);
    if (!r.ok()) {
      std::printf("%s: %s\n", argv[i], r.status().ToString().c_str());
      ++failed;
      continue;
    }
    const bool ok = r->AtRest() && r->lowest > -0.01;
    failed += !ok;
    std::printf("%s: %s (speed %.4f m/s, spin %.4f rad/s, lowest %.4f m, rests at %.4f m)\n",
                argv[i], ok ? "at rest" : "FAILED", r->final_speed, r->final_spin, r->lowest,
                r->rest_height);
  }
  std::printf("%d passed, %d failed\n", argc - 1 - failed, failed);
  return failed == 0 && argc > 1 ? 0 : 1;
}
