// instascene-scheduler: the job scheduler alone (SQLite queue under --data), using a remote store.
#include "services/node/node_flags.h"

int main(int argc, char** argv) {
  instascene::node::NodeOptions o;
  o.run_store = o.run_decomposition = o.run_training = false;
  return instascene::node::NodeMain(
      argc, argv, "instascene-scheduler: the per-scene job scheduler (needs --store)", o, true,
      false);
}
