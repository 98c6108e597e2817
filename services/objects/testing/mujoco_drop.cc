#include "services/objects/testing/mujoco_drop.h"

#include <mujoco/mujoco.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>

#include "absl/strings/str_cat.h"

namespace instascene::objects::testing {
namespace {

// The lowest world z of the body's collision geoms (mesh vertices through each geom's pose).
double LowestPoint(const mjModel* m, const mjData* d) {
  double lowest = std::numeric_limits<double>::infinity();
  for (int g = 0; g < m->ngeom; ++g) {
    if (m->geom_type[g] != mjGEOM_MESH || m->geom_contype[g] == 0) continue;
    const int mesh = m->geom_dataid[g];
    const float* vert = m->mesh_vert + 3 * m->mesh_vertadr[mesh];
    const mjtNum* pos = d->geom_xpos + 3 * g;
    const mjtNum* mat = d->geom_xmat + 9 * g;
    for (int v = 0; v < m->mesh_vertnum[mesh]; ++v) {
      const double z =
          pos[2] + mat[6] * vert[3 * v] + mat[7] * vert[3 * v + 1] + mat[8] * vert[3 * v + 2];
      lowest = std::min(lowest, z);
    }
  }
  return lowest;
}

}  // namespace

absl::StatusOr<DropResult> DropOntoFloor(const std::string& object_xml, double drop_height,
                                         double seconds) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::path(object_xml).parent_path();
  const fs::path scene = dir / "drop_scene.xml";
  std::ofstream(scene) << "<mujoco>\n  <include file=\"" << fs::path(object_xml).filename().string()
                       << "\"/>\n  <worldbody>\n    <geom name=\"floor\" type=\"plane\" "
                          "size=\"5 5 0.1\"/>\n  </worldbody>\n</mujoco>\n";
  char error[1000] = "";
  mjModel* m = mj_loadXML(scene.string().c_str(), nullptr, error, sizeof(error));
  std::error_code ec;
  fs::remove(scene, ec);
  if (m == nullptr)
    return absl::InvalidArgumentError(absl::StrCat(object_xml, ": MuJoCo: ", error));
  mjData* d = mj_makeData(m);
  mj_forward(m, d);
  d->qpos[2] += drop_height - LowestPoint(m, d);  // lowest point drop_height above the floor
  mj_forward(m, d);
  DropResult r;
  r.lowest = std::numeric_limits<double>::infinity();
  while (d->time < seconds) {
    mj_step(m, d);
    const double low = LowestPoint(m, d);
    if (!std::isfinite(low)) {
      r.finite = false;
      break;
    }
    r.lowest = std::min(r.lowest, low);
  }
  r.rest_height = LowestPoint(m, d);
  r.final_speed =
      std::sqrt(d->qvel[0] * d->qvel[0] + d->qvel[1] * d->qvel[1] + d->qvel[2] * d->qvel[2]);
  r.final_spin =
      std::sqrt(d->qvel[3] * d->qvel[3] + d->qvel[4] * d->qvel[4] + d->qvel[5] * d->qvel[5]);
  r.finite = r.finite && std::isfinite(r.final_speed) && std::isfinite(r.final_spin);
  mj_deleteData(d);
  mj_deleteModel(m);
  return r;
}

}  // namespace instascene::objects::testing
