#include "services/scheduler/job_proto.h"

#include "common/rpc/status.h"

namespace instascene::scheduler {

v1::JobState ToProto(JobState state) { return static_cast<v1::JobState>(static_cast<int>(state)); }

std::string StateName(v1::JobState state) {
  if (state < v1::JOB_STATE_QUEUED || state > v1::JOB_STATE_CANCELLED) return "unknown";
  return JobStateName(static_cast<JobState>(static_cast<int>(state)));
}

void ToProto(const JobProgress& p, v1::Progress* out) {
  out->set_phase(p.phase);
  out->set_step(p.step);
  out->set_total(p.total);
  out->set_loss(p.loss);
  out->set_eta_seconds(p.eta_seconds);
  out->set_message(p.message);
}

JobProgress FromProto(const v1::Progress& p) {
  JobProgress out;
  out.phase = p.phase();
  out.step = p.step();
  out.total = p.total();
  out.loss = p.loss();
  out.eta_seconds = p.eta_seconds();
  out.message = p.message();
  return out;
}

absl::StatusOr<FailureKind> FromProto(v1::FailureKind kind) {
  switch (kind) {
    case v1::FAILURE_KIND_RETRYABLE:
      return FailureKind::kRetryable;
    case v1::FAILURE_KIND_PERMANENT:
      return FailureKind::kPermanent;
    case v1::FAILURE_KIND_CANCELLED:
      return FailureKind::kCancelled;
    case v1::FAILURE_KIND_RELEASED:
      return FailureKind::kReleased;
    default:
      return absl::InvalidArgumentError("FailJob: kind is unspecified or unknown");
  }
}

v1::FailureKind ToProto(FailureKind kind) {
  switch (kind) {
    case FailureKind::kRetryable:
      return v1::FAILURE_KIND_RETRYABLE;
    case FailureKind::kPermanent:
      return v1::FAILURE_KIND_PERMANENT;
    case FailureKind::kCancelled:
      return v1::FAILURE_KIND_CANCELLED;
    case FailureKind::kReleased:
      return v1::FAILURE_KIND_RELEASED;
  }
  return v1::FAILURE_KIND_UNSPECIFIED;
}

void ToProto(const Job& j, v1::Job* out) {
  out->set_id(j.id);
  out->set_key(j.key);
  out->set_scene(j.scene);
  out->set_kind(j.kind);
  out->set_parameters_json(j.parameters_json);
  rpc::ToProto(j.scene_manifest, out->mutable_scene_manifest());
  for (const JobDependency& d : j.dependencies) {
    v1::JobDependency* dep = out->add_dependencies();
    dep->set_name(d.name);
    dep->set_job_id(d.job_id);
  }
  out->set_parent(j.parent);
  out->set_item(j.item);
  out->set_items(j.items);
  out->set_lease_ms(j.lease_ms);
  out->set_state(ToProto(j.state));
  out->set_priority(j.priority);
  out->set_attempts(j.attempts);
  out->set_max_attempts(j.max_attempts);
  if (!j.output_manifest.hash.empty())
    rpc::ToProto(j.output_manifest, out->mutable_output_manifest());
  out->set_error(j.error);
  out->set_worker_id(j.worker_id);
  ToProto(j.progress, out->mutable_progress());
  out->set_cancel_requested(j.cancel_requested);
  out->set_created_unix_ms(j.created_ms);
  out->set_updated_unix_ms(j.updated_ms);
  out->set_not_before_unix_ms(j.not_before_ms);
  out->set_lease_expires_unix_ms(j.lease_expires_ms);
}

}  // namespace instascene::scheduler
