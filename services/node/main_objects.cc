// instascene-objects: the Objects service (objects by id, point, click or ray) and the worker of
// the export stage; store and scheduler are reached by address.
#include <cstdio>

#include "services/node/node_flags.h"
#include "services/node/stage_services.h"
#include "services/stages/all_stages.h"

int main(int argc, char** argv) {
  instascene::pipeline::StageRegistry stages;
  if (absl::Status s = instascene::stages::RegisterStages(&stages); !s.ok()) {
    std::fprintf(stderr, "instascene-objects: %s\n", s.ToString().c_str());
    return 1;
  }
  instascene::node::NodeOptions o;
  o.run_store = o.run_scheduler = false;
  o.listen = "127.0.0.1:0";
  o.workers = {"objects"};
  return instascene::node::NodeMain(
      argc, argv,
      "instascene-objects: answers Objects queries and leases export jobs "
      "(needs --store and --scheduler)",
      o, true, true, stages, {instascene::node::ObjectsStageService()});
}
