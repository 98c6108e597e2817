// services/scheduler/job.h: the job model. A job is one stage of one scene with its parameters and
// its named inputs (the jobs it depends on: fan-in); a finished fan-out job creates child jobs, one
// per item of its output, and the jobs that wait for all of them. Its key (SHA-256 of the scene
// manifest, kind, canonical parameters, the keys of its dependencies by name and its item index)
// makes submission idempotent. Every state change goes through `Transition`, the one place that
// knows which moves are legal. Value types; thread-safe.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "common/store/digest.h"
#include "services/pipeline/plan.h"

namespace instascene::scheduler {

enum class JobState { kQueued = 1, kLeased, kRunning, kSucceeded, kFailed, kCancelled };

enum class JobEvent {
  kLease,     // a worker takes a queued, ready job
  kProgress,  // the worker reports progress (heartbeat)
  kSucceed,   // the worker completes it
  kRetry,     // failure or expired lease with attempts left: back to the queue (with backoff)
  kGiveUp,    // failure without retries left, or not retryable
  kCancel,    // cancelled (queued: at once; leased/running: when the worker acknowledges)
  kResubmit,  // a failed or cancelled job submitted again
};

// How a held job ended without success: one outcome, never a combination of flags.
enum class FailureKind {
  kRetryable,  // may succeed on another attempt (environment, crash, timeout): retried with backoff
  kPermanent,  // bad input or parameters: fails now, never retried
  kCancelled,  // the worker stopped because cancellation was requested
  kReleased,   // handed back unfinished (worker draining): queued again, attempt not counted
};

const char* JobStateName(JobState state);  // "queued", "leased", ...
absl::StatusOr<JobState> ParseJobState(absl::string_view name);
const char* JobEventName(JobEvent event);
const char* FailureKindName(FailureKind kind);
bool IsFinal(JobState state);
bool IsHeld(JobState state);  // leased or running: a worker holds it

// The single transition function. FailedPrecondition names the illegal move.
absl::StatusOr<JobState> Transition(JobState from, JobEvent event);

struct JobProgress {
  std::string phase;
  int64_t step = 0, total = 0;
  double loss = 0, eta_seconds = -1;
  std::string message;

  nlohmann::json ToJson() const;
  static JobProgress FromJson(const nlohmann::json& j);
};

// One named input of a job: the output of job `job_id` arrives under `name` (a stage kind, or
// "<kind>/<item>" for the fan-in of per-item jobs).
struct JobDependency {
  std::string name;
  std::string job_id;
  bool operator==(const JobDependency&) const = default;
};

using pipeline::InputMode;
using pipeline::PlannedInput;
using pipeline::PlannedStage;

// A pipeline submission: the stages in dependency order. Stages with a kEach or kAll input (and
// stages depending on them) are created when their fan-out source succeeds.
struct SubmitRequest {
  std::string scene;             // human name of the scene
  store::Digest scene_manifest;  // the scene's manifest in the store
  std::vector<PlannedStage> stages;
  int priority = 0;      // higher first
  int max_attempts = 3;  // leases before a job fails for good
};

struct Job {
  std::string id, key, scene, kind;
  std::string parameters_json;  // canonical
  store::Digest scene_manifest;
  std::vector<JobDependency> dependencies;  // named inputs (fan-in), sorted by name
  std::string parent;  // the fan-out job that created this one ("" = submitted directly)
  int64_t item = -1;   // index among the parent's items (-1: not a per-item job)
  int pending = 0;     // dependencies not yet succeeded (ready when 0)
  int64_t items = -1;  // fan-out jobs: items reported at completion (-1: none yet)
  nlohmann::json plans = nlohmann::json::array();  // fan-out jobs: deferred stages to create
  JobState state = JobState::kQueued;
  int priority = 0, attempts = 0, max_attempts = 3;
  store::Digest output_manifest;  // set when succeeded
  std::string error, worker_id, lease_token;
  JobProgress progress;
  bool cancel_requested = false;
  int64_t created_ms = 0, updated_ms = 0, not_before_ms = 0, lease_expires_ms = 0;
  int64_t lease_ms = 0;  // the lease length granted at the last lease; heartbeats renew with it
  int64_t seq = 0;       // submission order in the store (list pagination); set by the store

  const JobDependency* FindDependency(absl::string_view name) const;
};

// key = SHA-256 over (scene manifest, kind, canonical parameters, dependency keys by name, item,
// and the tenant when there is one): tenants never share jobs, even of identical scenes.
std::string JobKey(const store::Digest& scene_manifest, const std::string& kind,
                   const nlohmann::json& parameters,
                   const std::vector<std::pair<std::string, std::string>>& dependency_keys,
                   int64_t item, const std::string& tenant = "");
// Job ids are derived from keys: the same job has the same id everywhere.
std::string JobIdFromKey(const std::string& key);

}  // namespace instascene::scheduler
