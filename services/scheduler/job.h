// services/scheduler/job.h: the job model. A job is one stage (decompose, train, segment) of one
// scene with its parameters and inputs; its key (SHA-256 of the scene manifest, kind, canonical
// parameters and the dependency's key) makes submission idempotent. Every state change goes
// through `Transition`, the one place that knows which moves are legal. Value types; thread-safe.
#pragma once

#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "common/store/digest.h"

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

const char* JobStateName(JobState state);  // "queued", "leased", ...
absl::StatusOr<JobState> ParseJobState(absl::string_view name);
const char* JobEventName(JobEvent event);
bool IsFinal(JobState state);

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

// What a client asks for.
struct JobSpec {
  std::string scene;  // human name of the scene
  std::string kind;   // stage
  nlohmann::json parameters = nlohmann::json::object();
  store::Digest scene_manifest;  // the scene's manifest in the store
  std::string depends_on;        // job id whose output this job consumes ("" = none)
  int priority = 0;              // higher first
  int max_attempts = 3;          // leases before the job fails for good
};

struct Job {
  std::string id, key, scene, kind;
  std::string parameters_json;  // canonical
  store::Digest scene_manifest;
  std::string depends_on;
  JobState state = JobState::kQueued;
  int priority = 0, attempts = 0, max_attempts = 3;
  store::Digest output_manifest;  // set when succeeded
  std::string error, worker_id, lease_token;
  JobProgress progress;
  bool cancel_requested = false;
  int64_t created_ms = 0, updated_ms = 0, not_before_ms = 0, lease_expires_ms = 0;
};

// key = SHA-256 over (scene manifest, kind, canonical parameters, dependency key).
std::string JobKey(const JobSpec& spec, const std::string& dependency_key);
// Job ids are derived from keys: the same job has the same id everywhere.
std::string JobIdFromKey(const std::string& key);

}  // namespace instascene::scheduler
