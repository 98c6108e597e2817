// services/objects/testing/mujoco_drop.h: the simulator check of an exported object: MuJoCo loads
// its object.xml inside a scene with a floor, the object is held with its lowest collision point
// `drop_height` above the floor and released; after `seconds` of simulated time it must be at rest
// (no explosion: finite state and small velocities) and never below the floor (no tunnelling).
// Used by objects_test and by the objects_drop_check tool of tests/export_test.sh.
#pragma once

#include <string>

#include "absl/status/statusor.h"

namespace instascene::objects::testing {

struct DropResult {
  double final_speed = 0;  // m/s, centre of mass
  double final_spin = 0;   // rad/s
  double lowest = 0;       // lowest collision point over the run, m (floor at 0)
  double rest_height = 0;  // lowest collision point at the end, m
  bool finite = true;
  bool AtRest(double max_speed = 0.05, double max_spin = 0.5) const {
    return finite && final_speed < max_speed && final_spin < max_spin;
  }
};

absl::StatusOr<DropResult> DropOntoFloor(const std::string& object_xml, double drop_height = 0.05,
                                         double seconds = 1.0);

}  // namespace instascene::objects::testing
