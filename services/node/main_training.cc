// instascene-training: a training worker + service (click queries); store and scheduler remote.
#include "services/node/node_flags.h"

int main(int argc, char** argv) {
  instascene::node::NodeOptions o;
  o.run_store = o.run_scheduler = o.run_decomposition = false;
  o.listen = "127.0.0.1:0";
  return instascene::node::NodeMain(
      argc, argv,
      "instascene-training: leases train and segment jobs, answers queries (needs --store and "
      "--scheduler)",
      o, true, true);
}
