// services/node/node.h: one process hosting any subset of the services: the store, the scheduler
// and the stage workers (decomposition, training) with their gRPC adapters, all on one port.
// `instascene serve` runs everything (the embedded default: filesystem store + SQLite queue under
// --data); `instascene-store`, `instascene-scheduler`, `instascene-decomposition` and
// `instascene-training` run one role each and reach the others by address.
//
// Lifecycle: STARTING -> SERVING (health SERVING, ready file written) -> on SIGTERM/SIGINT DRAINING
// (workers stop leasing; running jobs get --drain-seconds to finish, then are handed back to the
// queue) -> STOPPED. Nothing acknowledged is lost: the queue and the store are durable.
#pragma once

#include <string>

#include "absl/status/status.h"
#include "common/store/blob_store.h"

namespace instascene::node {

struct NodeOptions {
  std::string data_dir = "instascene-data";  // store/, jobs.db, work/ live here
  std::string listen = "127.0.0.1:50051";    // host:port (port 0 = any free port)
  bool run_store = true;
  bool run_scheduler = true;
  bool run_decomposition = true;  // a worker leasing "decompose" jobs + its service
  bool run_training = true;       // a worker leasing "train" and "segment" jobs + its service
  std::string store_address;      // where the store is when !run_store
  std::string scheduler_address;  // where the scheduler is when !run_scheduler
  int lease_seconds = 30;         // job lease length; heartbeats renew it every lease/4
  int drain_seconds = 30;         // SIGTERM: how long running jobs may take to finish
  int num_threads = 0;            // per job; 0 = all cores
  int64_t cache_bytes = int64_t{20} << 30;  // per worker: input cache budget (0 = unlimited)
  std::string ready_file;  // written with the bound address once serving ("" = none)
  store::StoreOptions store_options;

  absl::Status Validate() const;
};

// Runs until SIGTERM or SIGINT, then drains. Call from main before starting other threads.
absl::Status RunNode(const NodeOptions& options);

}  // namespace instascene::node
