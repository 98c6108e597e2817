// clients/cli/job_view.h: jobs as the client commands show them (JSON, table labels, the tree
// of a scene's jobs, live progress) and the live watch of jobs until they finish.
#pragma once

#include <map>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "instascene/client/client.h"
#include "instascene/v1/scheduler.grpc.pb.h"

namespace instascene::cli {

// A job as the --json outputs print it.
nlohmann::json JobJson(const v1::Job& j);

// A job's label in tables: its kind, with the item index for per-item jobs.
std::string KindLabel(const v1::Job& j);

// The jobs of one scene as a tree: each job under its first dependency (fan-in jobs list the
// others), depth-first in submission order. Returns (depth, job) rows.
std::vector<std::pair<int, const v1::Job*>> JobTree(const std::vector<const v1::Job*>& jobs);

bool IsFinalState(v1::JobState s);

// Live progress of a held job ("" once the job is final: the last report is no longer news).
std::string ProgressText(const v1::Job& j);

// Streams job snapshots (the jobs `ids`, or every job of `scene`) until every watched job is
// final. Prints a line per state change and per progress step of 10 % to stderr; returns the
// final snapshots.
absl::StatusOr<std::map<std::string, v1::Job>> WatchJobs(client::Client& c,
                                                         const std::vector<std::string>& ids,
                                                         const std::string& scene);

}  // namespace instascene::cli
