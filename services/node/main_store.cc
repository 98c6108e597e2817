// instascene-store: the content-addressed blob store service alone.
#include "services/node/node_flags.h"

int main(int argc, char** argv) {
  instascene::node::NodeOptions o;
  o.run_scheduler = false;
  return instascene::node::NodeMain(
      argc, argv, "instascene-store: the content-addressed Gaussian store service", o, false, false,
      instascene::pipeline::StageRegistry());
}
