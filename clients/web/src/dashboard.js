// dashboard.js: the queue for operators (admin tokens): jobs by stage and state, the oldest queued
// age per stage, throughput and failure rate over time (sampled while the page is open), recent
// failures with their reasons, and the workers with what each is running (from the leases of
// running jobs). Polls every POLL_MS; cancel acts through the scheduler.
import * as api from "./api.js";
import { el, formatSeconds, formatTime, showError, sparkline } from "./ui.js";

const POLL_MS = 3000;
const HISTORY_MINUTES = 30;
const HISTORY_JOBS = 500; // finished jobs of each outcome the charts are drawn from

export function render(main) {
  const note = el("p", { id: "dashboard-note" }, "Loading…");
  const totals = el("p", { id: "queue-totals" });
  const stagesBody = el("tbody");
  const charts = el("div", { class: "charts" });
  const failures = el("tbody");
  const workers = el("tbody");
  main.replaceChildren(el("section", { class: "card" },
    el("h1", {}, "Queue"),
    note,
    totals,
    el("h2", {}, "By stage"),
    el("table", { id: "stages" },
      el("caption", { class: "sr-only" }, "Jobs by stage and state"),
      el("thead", {}, el("tr", {}, ["Stage", ...api.STATES, "Oldest queued"].map((h) => el("th", { scope: "col" }, h)))),
      stagesBody),
    el("h2", {}, "Throughput and failures"),
    charts,
    el("h2", {}, "Workers"),
    el("table", { id: "workers" },
      el("caption", { class: "sr-only" }, "Workers and their jobs"),
      el("thead", {}, el("tr", {}, ["Worker", "Job", "Scene", "Progress", "Lease until", ""].map((h) => el("th", { scope: "col" }, h)))),
      workers),
    el("h2", {}, "Recent failures"),
    el("table", { id: "failures" },
      el("caption", { class: "sr-only" }, "Failed jobs and their reasons"),
      el("thead", {}, el("tr", {}, ["Job", "Scene", "Attempts", "When", "Reason", ""].map((h) => el("th", { scope: "col" }, h)))),
      failures)));

  let timer = null;
  let stopped = false;

  // Finished jobs per minute and the share that failed, over the last HISTORY_MINUTES minutes.
  function drawCharts(succeeded, failed, now) {
    const start = now - HISTORY_MINUTES * 60000;
    const done = new Array(HISTORY_MINUTES).fill(0);
    const bad = new Array(HISTORY_MINUTES).fill(0);
    const bucket = (job) => Math.floor((Number(job.updated_unix_ms) - start) / 60000);
    for (const job of succeeded) { const b = bucket(job); if (b >= 0 && b < HISTORY_MINUTES) done[b] += 1; }
    for (const job of failed) { const b = bucket(job); if (b >= 0 && b < HISTORY_MINUTES) { done[b] += 1; bad[b] += 1; } }
    const rates = done.map((n, i) => [start + i * 60000, n]);
    const failures = done.map((n, i) => [start + i * 60000, n ? bad[i] / n : 0]);
    const total = done.reduce((a, b) => a + b, 0);
    const totalBad = bad.reduce((a, b) => a + b, 0);
    charts.replaceChildren(
      el("figure", {}, sparkline(rates, { label: "finished jobs per minute, last 30 minutes" }),
        el("figcaption", {}, `Finished jobs per minute (30 min): ${(total / HISTORY_MINUTES).toFixed(1)} on average, ${done[HISTORY_MINUTES - 1]} in the last minute`)),
      el("figure", {}, sparkline(failures, { label: "share of finished jobs that failed, per minute" }),
        el("figcaption", {}, `Failure rate (30 min): ${total ? ((100 * totalBad) / total).toFixed(0) : 0} %`)));
  }

  function cancelButton(job) {
    return el("button", {
      type: "button",
      "aria-label": `Cancel job ${job.id}`,
      onclick: () => api.post(`/jobs/${job.id}/cancel`).then(poll).catch((e) => showError(note, e)),
    }, "Cancel");
  }

  async function poll() {
    try {
      const [stats, succeeded, failed, running] = await Promise.all([
        api.get("/queue"),
        api.get(`/jobs?state=succeeded&limit=${HISTORY_JOBS}`),
        api.get(`/jobs?state=failed&limit=${HISTORY_JOBS}`),
        api.get("/jobs?state=running&limit=200"),
      ]);
      const byState = stats.jobs_by_state || {};
      totals.textContent = `${stats.scenes} scenes · ${api.STATES.map((s) => `${byState[s] || 0} ${s}`).join(" · ")} · oldest queued ${formatSeconds(Number(stats.oldest_queued_age_ms) / 1000) || "none"}`;
      stagesBody.replaceChildren(...(stats.stages || []).map((s) => el("tr", { "data-stage": s.stage },
        el("th", { scope: "row" }, s.stage),
        ...api.STATES.map((state) => el("td", { "data-state": state }, String((s.jobs_by_state || {})[state] || 0))),
        el("td", {}, Number(s.oldest_queued_age_ms) ? formatSeconds(Number(s.oldest_queued_age_ms) / 1000) : "–"))));
      const now = Date.now();
      drawCharts(succeeded.jobs || [], failed.jobs || [], now);
      workers.replaceChildren(...(running.jobs || []).map((job) => el("tr", {},
        el("td", {}, job.worker_id),
        el("td", {}, `${job.kind}${Number(job.item) >= 0 ? ` #${job.item}` : ""}`),
        el("td", {}, el("a", { href: `#/scenes/${encodeURIComponent(job.scene)}` }, job.scene)),
        el("td", {}, job.progress?.phase ? `${job.progress.phase} ${job.progress.step}/${job.progress.total}` : ""),
        el("td", {}, formatTime(job.lease_expires_unix_ms)),
        el("td", {}, cancelButton(job)))));
      if (!(running.jobs || []).length) workers.replaceChildren(el("tr", {}, el("td", { colspan: 6 }, "No job is running.")));
      failures.replaceChildren(...(failed.jobs || []).slice(0, 20).map((job) => el("tr", {},
        el("td", {}, job.kind),
        el("td", {}, el("a", { href: `#/scenes/${encodeURIComponent(job.scene)}` }, job.scene)),
        el("td", {}, `${job.attempts}/${job.max_attempts}`),
        el("td", {}, formatTime(job.updated_unix_ms)),
        el("td", { class: "error-text" }, job.error),
        el("td", {}, el("button", {
          type: "button",
          "aria-label": `Retry the failed jobs of scene ${job.scene}`,
          onclick: () => api.get(`/jobs?scene=${encodeURIComponent(job.scene)}&limit=1000`)
            .then((answer) => api.resubmitScene(job.scene, answer.jobs || []))
            .then(poll)
            .catch((e) => showError(note, e)),
        }, "Retry")))));
      note.textContent = `Updated ${new Date(now).toLocaleTimeString()}.`;
      note.classList.remove("error");
    } catch (e) {
      showError(note, e.status === "PERMISSION_DENIED" ? new Error("The queue dashboard needs an admin token.") : e);
    }
    if (!stopped) timer = setTimeout(poll, POLL_MS);
  }
  poll();
  return () => {
    stopped = true;
    clearTimeout(timer);
  };
}
