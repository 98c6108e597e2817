// instascene-decomposition: a decomposition worker + service; reaches store and scheduler remotely.
#include "services/node/node_flags.h"

int main(int argc, char** argv) {
  instascene::node::NodeOptions o;
  o.run_store = o.run_scheduler = o.run_training = false;
  o.listen = "127.0.0.1:0";
  return instascene::node::NodeMain(
      argc, argv, "instascene-decomposition: leases decompose jobs (needs --store and --scheduler)",
      o, true, true);
}
