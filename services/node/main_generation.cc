// instascene-generation: the generation stage service (a worker + its gRPC adapter); store and
// scheduler are reached by address.
#include <cstdio>

#include "services/node/node_flags.h"
#include "services/node/stage_services.h"
#include "services/stages/all_stages.h"

int main(int argc, char** argv) {
  instascene::pipeline::StageRegistry stages;
  if (absl::Status s = instascene::stages::RegisterStages(&stages); !s.ok()) {
    std::fprintf(stderr, "instascene-generation: %s\n", s.ToString().c_str());
    return 1;
  }
  instascene::node::NodeOptions o;
  o.run_store = o.run_scheduler = false;
  o.listen = "127.0.0.1:0";
  o.workers = {"generation"};
  return instascene::node::NodeMain(argc, argv,
                                    "instascene-generation: leases complete jobs (one per object) "
                                    "(needs --store and --scheduler)",
                                    o, true, true, stages,
                                    {instascene::node::GenerationStageService()});
}
