// instascene-scheduler: the job scheduler alone (SQLite queue under --data), using a remote store.
// It validates stage parameters through the stages' specs and codecs (instascene_stage_specs),
// without linking any stage library.
#include <cstdio>

#include "services/node/node_flags.h"
#include "services/stages/all_stages.h"

int main(int argc, char** argv) {
  instascene::pipeline::StageRegistry stages;
  if (absl::Status s = instascene::stages::RegisterStageSpecs(&stages); !s.ok()) {
    std::fprintf(stderr, "instascene-scheduler: %s\n", s.ToString().c_str());
    return 1;
  }
  instascene::node::NodeOptions o;
  o.run_store = false;
  return instascene::node::NodeMain(
      argc, argv, "instascene-scheduler: the per-scene job scheduler (needs --store)", o, true,
      false, stages);
}
