// `instascene object` and `instascene objects`: what a robot asks a running server for. One
// object by id, 3D point, click or ray (its pose, metric size and artefacts, downloaded and
// verified with --out), or the list of a scene's objects. Both go through the C++ client library.
#include <cstdio>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "clients/cli/cli.h"
#include "clients/cli/connection.h"
#include "common/core/status.h"
#include "instascene/client/client.h"

namespace instascene::cli {
namespace {

nlohmann::json ObjectJson(const client::ObjectInfo& o) {
  const client::Pose& p = o.world_from_object;
  nlohmann::json artefacts = nlohmann::json::array();
  for (const client::Artefact& a : o.artefacts)
    artefacts.push_back(
        {{"path", a.path}, {"sha256", a.sha256}, {"bytes", a.bytes}, {"media_type", a.media_type}});
  return {{"scene", o.scene},
          {"id", o.id},
          {"source", o.source},
          {"units", o.units},
          {"meters_per_unit", o.meters_per_unit},
          {"world_from_object",
           {{"translation", {p.translation.x, p.translation.y, p.translation.z}},
            {"quaternion_xyzw", {p.qx, p.qy, p.qz, p.qw}}}},
          {"extent", {o.extent.x, o.extent.y, o.extent.z}},
          {"completion", o.completion},
          {"completed_share", o.completed_share},
          {"gaussians", o.gaussians},
          {"artefacts", artefacts},
          {"query_us", o.query_microseconds},
          {"index_loaded", o.index_loaded}};
}

void PrintObject(const client::ObjectInfo& o) {
  const client::Pose& p = o.world_from_object;
  std::printf("object %u of scene %s: %s (%s)\n", o.id, o.scene.c_str(), o.completion.c_str(),
              o.source.c_str());
  std::printf("  pose  t = (%.4f, %.4f, %.4f)  q_xyzw = (%.4f, %.4f, %.4f, %.4f)  [%s]\n",
              p.translation.x, p.translation.y, p.translation.z, p.qx, p.qy, p.qz, p.qw,
              o.units.c_str());
  std::printf("  size  %.4f x %.4f x %.4f  [%s]\n", o.extent.x, o.extent.y, o.extent.z,
              o.units.c_str());
  for (const client::Artefact& a : o.artefacts)
    std::printf("  %-24s %10lld bytes  %s\n", a.path.c_str(), static_cast<long long>(a.bytes),
                a.media_type.c_str());
}

struct ObjectArgs {
  std::string server = kDefaultServer, store, scene, view, pixel, point, ray, out;
  ConnectionFlags connection;
  int64_t id = -1;
  double max_distance = 0;
  bool json = false;
};

// The one selector the flags give: --id, --point, --view with --pixel, or --ray.
absl::StatusOr<client::ObjectSelector> SelectorOf(const ObjectArgs& a) {
  const int given = (a.id >= 0) + !a.point.empty() + !a.pixel.empty() + !a.ray.empty();
  if (given != 1)
    return absl::InvalidArgumentError(
        "give exactly one of --id, --point, --view with --pixel, or --ray");
  if (a.pixel.empty() != a.view.empty())
    return absl::InvalidArgumentError("--pixel and --view go together");
  if (a.id >= 0) {
    if (a.id > 0xffffffffLL) return absl::InvalidArgumentError("--id must be below 2^32");
    return client::ObjectSelector::Id(static_cast<uint32_t>(a.id));
  }
  if (!a.point.empty()) {
    ASSIGN_OR_RETURN(auto v, ParseNumbers(a.point, 3, "--point", "X,Y,Z"));
    return client::ObjectSelector::Point({v[0], v[1], v[2]}, a.max_distance);
  }
  if (!a.pixel.empty()) {
    ASSIGN_OR_RETURN(auto v, ParseNumbers(a.pixel, 2, "--pixel", "X,Y"));
    return client::ObjectSelector::Click(a.view, static_cast<int>(v[0]), static_cast<int>(v[1]));
  }
  ASSIGN_OR_RETURN(auto v, ParseNumbers(a.ray, 6, "--ray", "OX,OY,OZ,DX,DY,DZ"));
  return client::ObjectSelector::Ray({v[0], v[1], v[2]}, {v[3], v[4], v[5]});
}

absl::Status RunObject(const ObjectArgs& a) {
  ASSIGN_OR_RETURN(const client::ObjectSelector selector, SelectorOf(a));
  ASSIGN_OR_RETURN(std::unique_ptr<client::Client> c,
                   ConnectClient(a.connection, a.server, a.store));
  ASSIGN_OR_RETURN(client::ObjectInfo object, c->GetObject(a.scene, selector));
  PrintObject(object);
  nlohmann::json out = ObjectJson(object);
  if (!a.out.empty()) {
    ASSIGN_OR_RETURN(client::Transfer t, c->DownloadObject(object, a.out));
    std::printf("downloaded %lld files (%.2f MB, digests verified) into %s\n",
                static_cast<long long>(t.files), t.bytes / 1e6, a.out.c_str());
    out["downloaded"] = {{"files", t.files}, {"bytes", t.bytes}, {"out", a.out}};
  }
  if (a.json) PrintJsonLine(out.dump());
  return absl::OkStatus();
}

struct ListArgs {
  std::string server = kDefaultServer, scene;
  ConnectionFlags connection;
  bool json = false;
};

absl::Status RunListObjects(const ListArgs& a) {
  ASSIGN_OR_RETURN(std::unique_ptr<client::Client> c, ConnectClient(a.connection, a.server));
  ASSIGN_OR_RETURN(std::vector<client::ObjectInfo> objects, c->ListObjects(a.scene));
  std::printf("%-5s %-9s %-26s %-30s %s\n", "ID", "SOURCE", "SIZE", "COMPLETION", "ARTEFACTS");
  nlohmann::json all = nlohmann::json::array();
  for (const client::ObjectInfo& o : objects) {
    const std::string size = absl::StrFormat("%.3f x %.3f x %.3f %s", o.extent.x, o.extent.y,
                                             o.extent.z, o.units == "metres" ? "m" : "u");
    std::printf("%-5u %-9s %-26s %-30s %zu\n", o.id, o.source.c_str(), size.c_str(),
                o.completion.substr(0, 30).c_str(), o.artefacts.size());
    all.push_back(ObjectJson(o));
  }
  if (a.json) PrintJsonLine(nlohmann::json({{"objects", all}}).dump());
  return absl::OkStatus();
}

void AddListObjectsCommand(CLI::App& app, Action* action) {
  auto list = std::make_shared<ListArgs>();
  CLI::App* ls = app.add_subcommand(
      "objects", "The objects of a scene on a server: id, source, size, completion, artefacts");
  ls->add_option("--scene", list->scene, "Scene name")->required();
  ls->add_option("--server", list->server,
                 "The Objects service's address (`instascene serve`, or instascene-objects)")
      ->capture_default_str();
  AddConnectionFlags(ls, &list->connection);
  ls->add_flag("--json", list->json, "Print {\"objects\": [...]} as the last stdout line");
  ls->callback([list, action] { *action = [list] { return RunListObjects(*list); }; });
}

}  // namespace

void AddObjectCommands(CLI::App& app, Action* action) {
  auto args = std::make_shared<ObjectArgs>();
  CLI::App* cmd = app.add_subcommand(
      "object",
      "One object of a scene on a server, by --id, --point, --view + --pixel or --ray: its pose, "
      "size in metres (metric scenes) and artefacts; --out downloads them (digests verified)");
  cmd->add_option("--scene", args->scene, "Scene name")->required();
  cmd->add_option("--id", args->id, "Object (instance) id");
  cmd->add_option("--point", args->point, "Or the object nearest a 3D point X,Y,Z (world)");
  cmd->add_option("--max-distance", args->max_distance,
                  "--point: search radius in scene units (0 = 2 % of the scene's diagonal)");
  cmd->add_option("--view", args->view, "With --pixel: the view clicked (name or index)");
  cmd->add_option("--pixel", args->pixel, "Or the object drawn at pixel X,Y of --view");
  cmd->add_option("--ray", args->ray, "Or the object a ray OX,OY,OZ,DX,DY,DZ meets (world)");
  cmd->add_option("--out", args->out, "Download its artefacts into this directory");
  cmd->add_option("--server", args->server,
                  "The Objects service's address (`instascene serve`, or instascene-objects)")
      ->capture_default_str();
  cmd->add_option("--store", args->store, "Store address (default: --server)");
  AddConnectionFlags(cmd, &args->connection);
  cmd->add_flag("--json", args->json, "Print the object as one JSON line");
  cmd->callback([args, action] { *action = [args] { return RunObject(*args); }; });
  AddListObjectsCommand(app, action);
}

}  // namespace instascene::cli
