#include "services/scheduler/job.h"

#include "absl/strings/str_cat.h"

namespace instascene::scheduler {

const char* JobStateName(JobState state) {
  switch (state) {
    case JobState::kQueued:
      return "queued";
    case JobState::kLeased:
      return "leased";
    case JobState::kRunning:
      return "running";
    case JobState::kSucceeded:
      return "succeeded";
    case JobState::kFailed:
      return "failed";
    case JobState::kCancelled:
      return "cancelled";
  }
  return "unknown";
}

absl::StatusOr<JobState> ParseJobState(absl::string_view name) {
  for (JobState s : {JobState::kQueued, JobState::kLeased, JobState::kRunning, JobState::kSucceeded,
                     JobState::kFailed, JobState::kCancelled}) {
    if (name == JobStateName(s)) return s;
  }
  return absl::InvalidArgumentError(absl::StrCat("unknown job state '", name, "'"));
}

const char* JobEventName(JobEvent event) {
  switch (event) {
    case JobEvent::kLease:
      return "lease";
    case JobEvent::kProgress:
      return "report progress on";
    case JobEvent::kSucceed:
      return "complete";
    case JobEvent::kRetry:
      return "retry";
    case JobEvent::kGiveUp:
      return "fail";
    case JobEvent::kCancel:
      return "cancel";
    case JobEvent::kResubmit:
      return "resubmit";
  }
  return "?";
}

bool IsFinal(JobState state) {
  return state == JobState::kSucceeded || state == JobState::kFailed ||
         state == JobState::kCancelled;
}

bool IsHeld(JobState state) { return state == JobState::kLeased || state == JobState::kRunning; }

absl::StatusOr<JobState> Transition(JobState from, JobEvent event) {
  const bool held = from == JobState::kLeased || from == JobState::kRunning;
  switch (event) {
    case JobEvent::kLease:
      if (from == JobState::kQueued) return JobState::kLeased;
      break;
    case JobEvent::kProgress:
      if (held) return JobState::kRunning;
      break;
    case JobEvent::kSucceed:
      if (held) return JobState::kSucceeded;
      break;
    case JobEvent::kRetry:
      if (held) return JobState::kQueued;
      break;
    case JobEvent::kGiveUp:
      if (held) return JobState::kFailed;
      break;
    case JobEvent::kCancel:
      if (from == JobState::kQueued || held) return JobState::kCancelled;
      break;
    case JobEvent::kResubmit:
      if (from == JobState::kFailed || from == JobState::kCancelled) return JobState::kQueued;
      break;
  }
  return absl::FailedPreconditionError(
      absl::StrCat("cannot ", JobEventName(event), " a ", JobStateName(from), " job"));
}

nlohmann::json JobProgress::ToJson() const {
  return {{"phase", phase},
          {"step", step},
          {"total", total},
          {"loss", loss},
          {"eta_seconds", eta_seconds},
          {"message", message}};
}

JobProgress JobProgress::FromJson(const nlohmann::json& j) {
  JobProgress p;
  if (!j.is_object()) return p;
  p.phase = j.value("phase", "");
  p.step = j.value("step", int64_t{0});
  p.total = j.value("total", int64_t{0});
  p.loss = j.value("loss", 0.0);
  p.eta_seconds = j.value("eta_seconds", -1.0);
  p.message = j.value("message", "");
  return p;
}

std::string JobKey(const store::Digest& scene_manifest, const std::string& kind,
                   const nlohmann::json& parameters,
                   const std::vector<std::pair<std::string, std::string>>& dependency_keys,
                   int64_t item, const std::string& tenant) {
  nlohmann::json deps = nlohmann::json::object();
  for (const auto& [name, key] : dependency_keys) deps[name] = key;
  nlohmann::json j = {{"scene_manifest", scene_manifest.ToString()},
                      {"kind", kind},
                      {"parameters", parameters},
                      {"dependencies", deps},
                      {"item", item}};
  if (!tenant.empty()) j["tenant"] = tenant;  // keys without a tenant stay what they were
  return store::ComputeDigest(j.dump()).hash;
}

const JobDependency* Job::FindDependency(absl::string_view name) const {
  for (const JobDependency& d : dependencies)
    if (d.name == name) return &d;
  return nullptr;
}

const char* FailureKindName(FailureKind kind) {
  switch (kind) {
    case FailureKind::kRetryable:
      return "retryable";
    case FailureKind::kPermanent:
      return "permanent";
    case FailureKind::kCancelled:
      return "cancelled";
    case FailureKind::kReleased:
      return "released";
  }
  return "?";
}

std::string JobIdFromKey(const std::string& key) { return absl::StrCat("j", key.substr(0, 15)); }

}  // namespace instascene::scheduler
