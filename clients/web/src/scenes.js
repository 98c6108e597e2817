// scenes.js: the scenes list and one scene's jobs (the DAG: each job with the jobs it depends on),
// kept live by the gateway's Server-Sent Events: state, phase, step, loss and ETA per job.
import * as api from "./api.js";
import { announce, el, formatSeconds, formatTime, showError } from "./ui.js";

const MAX_LISTED_JOBS = 2000;

async function allJobs(query) {
  const jobs = [];
  let page = "";
  do {
    const params = new URLSearchParams({ ...query, limit: "500" });
    if (page) params.set("page_token", page);
    const answer = await api.get(`/jobs?${params}`);
    jobs.push(...(answer.jobs || []));
    page = answer.next_page_token || "";
  } while (page && jobs.length < MAX_LISTED_JOBS);
  return jobs;
}

export function renderList(main) {
  const body = el("tbody");
  const note = el("p", {}, "Loading…");
  main.replaceChildren(el("section", { class: "card" },
    el("h1", {}, "Scenes"),
    note,
    el("table", { id: "scenes" },
      el("caption", { class: "sr-only" }, "Scenes and their jobs by state"),
      el("thead", {}, el("tr", {}, ["Scene", "Jobs", "Succeeded", "Running", "Failed", "Updated", ""].map((h) => el("th", { scope: "col" }, h)))),
      body)));
  allJobs({}).then((jobs) => {
    const scenes = new Map();
    for (const job of jobs) {
      const s = scenes.get(job.scene) || { name: job.scene, jobs: 0, states: {}, updated: 0 };
      s.jobs += 1;
      const state = api.stateName(job.state);
      s.states[state] = (s.states[state] || 0) + 1;
      s.updated = Math.max(s.updated, Number(job.updated_unix_ms));
      scenes.set(job.scene, s);
    }
    const sorted = [...scenes.values()].sort((a, b) => b.updated - a.updated);
    note.textContent = sorted.length ? `${sorted.length} scenes.` : "No scenes yet: upload one.";
    body.replaceChildren(...sorted.map((s) => el("tr", {},
      el("td", {}, el("a", { href: `#/scenes/${encodeURIComponent(s.name)}` }, s.name)),
      el("td", {}, String(s.jobs)),
      el("td", {}, String(s.states.succeeded || 0)),
      el("td", {}, String((s.states.running || 0) + (s.states.leased || 0))),
      el("td", {}, String(s.states.failed || 0)),
      el("td", {}, formatTime(s.updated)),
      el("td", {}, el("a", { href: `#/viewer/${encodeURIComponent(s.name)}` }, "View")))));
  }).catch((e) => showError(note, e));
  return null;
}

function progressCell(job) {
  const p = job.progress || {};
  const state = api.stateName(job.state);
  if (state === "succeeded") return el("span", {}, "done");
  if (!p.phase) return el("span", {}, state === "failed" ? "" : "waiting");
  const total = Number(p.total);
  const step = Number(p.step);
  const parts = [p.phase];
  if (total > 0) parts.push(`${step}/${total}`);
  if (p.loss) parts.push(`loss ${Number(p.loss).toPrecision(3)}`);
  if (Number(p.eta_seconds) >= 0 && state === "running") parts.push(`ETA ${formatSeconds(Number(p.eta_seconds))}`);
  return el("span", {},
    total > 0 ? el("progress", { max: total, value: step, "aria-label": `${job.kind} progress` }) : null,
    ` ${parts.join(" · ")}`);
}

function jobLabel(job) {
  return Number(job.item) >= 0 ? `${job.kind} #${job.item}` : job.kind;
}

export function renderScene(main, scene) {
  const rows = new Map(); // job id -> {job, row}
  const body = el("tbody");
  const summary = el("p", { id: "scene-summary" }, "Loading…");
  const viewerLink = el("a", { href: `#/viewer/${encodeURIComponent(scene)}`, class: "button" }, "Open the viewer");
  const cancel = el("button", { type: "button" }, "Cancel the scene's jobs");
  const retry = el("button", { type: "button", id: "retry-scene" }, "Retry failed and cancelled jobs");
  // Deleting: once every job has ended (the scheduler refuses before); its blobs go with the
  // store's next garbage collection.
  const remove = el("button", { type: "button", id: "delete-scene", disabled: true }, "Delete the scene");
  main.replaceChildren(el("section", { class: "card" },
    el("h1", {}, `Scene ${scene}`),
    summary,
    el("div", { class: "actions" }, viewerLink, cancel, retry, remove),
    el("table", { id: "jobs" },
      el("caption", { class: "sr-only" }, "The scene's jobs"),
      el("thead", {}, el("tr", {}, ["Stage", "State", "Progress", "Inputs", "Attempts", "Worker", "Error", ""].map((h) => el("th", { scope: "col" }, h)))),
      body)));
  const byId = () => new Map([...rows.values()].map((r) => [r.job.id, r.job]));

  function update(job) {
    const entry = rows.get(job.id) || {};
    const jobs = byId();
    jobs.set(job.id, job);
    const inputs = (job.dependencies || []).map((d) => jobs.get(d.job_id)).filter(Boolean).map(jobLabel).join(", ");
    const state = api.stateName(job.state);
    const cancelJob = el("button", {
      type: "button",
      "aria-label": `Cancel ${jobLabel(job)}`,
      onclick: () => api.post(`/jobs/${job.id}/cancel`).then(update).catch((e) => showError(summary, e)),
    }, "Cancel");
    const row = el("tr", { "data-job": job.id, "data-state": state },
      el("td", {}, jobLabel(job)),
      el("td", { class: `state ${state}` }, state),
      el("td", {}, progressCell(job)),
      el("td", {}, inputs),
      el("td", {}, `${job.attempts}/${job.max_attempts}`),
      el("td", {}, job.worker_id || ""),
      el("td", { class: "error-text" }, job.error || ""),
      el("td", {}, ["succeeded", "failed", "cancelled"].includes(state) ? "" : cancelJob));
    if (entry.row) entry.row.replaceWith(row);
    else body.append(row);
    rows.set(job.id, { job, row });
    const counts = {};
    for (const { job: j } of rows.values()) {
      const s = api.stateName(j.state);
      counts[s] = (counts[s] || 0) + 1;
    }
    summary.textContent = `${rows.size} jobs: ${Object.entries(counts).map(([s, n]) => `${n} ${s}`).join(", ")}`;
    summary.dataset.done = String(rows.size > 0 && [...rows.values()].every(({ job: j }) => ["succeeded", "failed", "cancelled"].includes(api.stateName(j.state))));
    remove.disabled = summary.dataset.done !== "true";
  }

  let source = null;
  cancel.addEventListener("click", () =>
    api.post(`/scenes/${encodeURIComponent(scene)}/cancel`).catch((e) => showError(summary, e)));
  remove.addEventListener("click", async () => {
    if (!window.confirm(`Delete scene ${scene} and its ${rows.size} jobs? Their results are removed from the store at its next garbage collection.`)) return;
    try {
      source?.close();
      const deleted = await api.del(`/scenes/${encodeURIComponent(scene)}`);
      rows.clear();
      body.replaceChildren();
      remove.disabled = true;
      summary.dataset.deleted = "true";
      summary.textContent = `Deleted ${Number(deleted.deleted_jobs || 0)} jobs of scene ${scene}.`;
      announce(summary.textContent);
    } catch (e) {
      showError(summary, e);
    }
  });
  retry.addEventListener("click", async () => {
    try {
      await api.resubmitScene(scene, [...rows.values()].map((r) => r.job));
      source?.close();
      const jobs = await allJobs({ scene });
      for (const job of jobs) update(job);
      source = api.watch({ scene }, update, null, (e) => showError(summary, e));
    } catch (e) {
      showError(summary, e);
    }
  });
  allJobs({ scene }).then((jobs) => {
    jobs.sort((a, b) => Number(a.created_unix_ms) - Number(b.created_unix_ms));
    for (const job of jobs) update(job);
    if (!jobs.length) summary.textContent = "No jobs for this scene.";
    // Event latency (the job's update time on the scheduler to its arrival here; one clock on a
    // single machine), for the measurements in docs/PERFORMANCE.md: each job's first event on
    // the stream is its current state, not a change, and is not counted.
    const seen = new Set();
    window.instasceneEventLatencies = [];
    source = api.watch({ scene }, (job) => {
      if (seen.has(job.id)) window.instasceneEventLatencies.push(Date.now() - Number(job.updated_unix_ms));
      seen.add(job.id);
      update(job);
    }, null, (e) => showError(summary, e));
  }).catch((e) => showError(summary, e));
  return () => source?.close();
}
