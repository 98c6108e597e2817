// api.js: the gateway's /api/v1 (docs/SERVICES.md "HTTP gateway") with the user's bearer token.
// Errors are thrown as ApiError carrying the gRPC status name and message the gateway sent.

const TOKEN_KEY = "instascene.token";

export class ApiError extends Error {
  constructor(httpStatus, status, message) {
    super(`${status}: ${message}`);
    this.httpStatus = httpStatus;
    this.status = status;
  }
}

export function token() {
  return sessionStorage.getItem(TOKEN_KEY) || "";
}

export function setToken(value) {
  if (value) sessionStorage.setItem(TOKEN_KEY, value.trim());
  else sessionStorage.removeItem(TOKEN_KEY);
}

function headers(extra = {}) {
  const h = { ...extra };
  if (token()) h.Authorization = `Bearer ${token()}`;
  return h;
}

async function check(response) {
  if (response.ok) return response;
  let status = `HTTP_${response.status}`;
  let message = response.statusText;
  try {
    const body = await response.json();
    if (body.error) ({ status, message } = body.error);
  } catch {
    // not JSON: keep the HTTP status
  }
  throw new ApiError(response.status, status, message);
}

export async function get(path) {
  return (await check(await fetch(`api/v1${path}`, { headers: headers() }))).json();
}

export async function post(path, body = {}) {
  const response = await fetch(`api/v1${path}`, {
    method: "POST",
    headers: headers({ "Content-Type": "application/json" }),
    body: JSON.stringify(body),
  });
  return (await check(response)).json();
}

export async function del(path) {
  return (await check(await fetch(`api/v1${path}`, { method: "DELETE", headers: headers() }))).json();
}

// One chunk of a resumable blob upload at `offset` (Upload-Offset).
export async function putChunk(digest, offset, bytes, signal) {
  const response = await fetch(`api/v1/blobs/${digest.hash}/${digest.size_bytes}`, {
    method: "PUT",
    headers: headers({ "Content-Type": "application/octet-stream", "Upload-Offset": String(offset) }),
    body: bytes,
    signal,
  });
  return (await check(response)).json();
}

// The blob's bytes (an ArrayBuffer).
export async function blob(digest, name = "") {
  const query = name ? `?name=${encodeURIComponent(name)}` : "";
  const response = await fetch(`api/v1/blobs/${digest.hash}/${digest.size_bytes}${query}`, {
    headers: headers(),
  });
  return (await check(response)).arrayBuffer();
}

export async function blobJson(digest) {
  return JSON.parse(new TextDecoder().decode(await blob(digest)));
}

// "hash/size" (manifest file entries) -> {hash, size_bytes}
export function parseDigest(text) {
  const [hash, size] = text.split("/");
  return { hash, size_bytes: Number(size) };
}

// Live job events (Server-Sent Events); EventSource cannot send headers, so the token travels as
// access_token. Returns the EventSource; `onJob(job)` per change, `onEnd()` when all are final.
export function watch(query, onJob, onEnd, onError) {
  const params = new URLSearchParams(query);
  if (token()) params.set("access_token", token());
  const source = new EventSource(`api/v1/events?${params}`);
  source.addEventListener("job", (e) => onJob(JSON.parse(e.data)));
  source.addEventListener("end", () => {
    source.close();
    onEnd?.();
  });
  source.addEventListener("error", (e) => {
    // The gateway's own "error" event carries the status; a dropped connection (no data)
    // reconnects by itself and the first events after it are every job's current state.
    if (e.data) {
      onError?.(JSON.parse(e.data));
      source.close();
    } else if (source.readyState === EventSource.CLOSED) {
      onError?.({ status: "UNAVAILABLE", message: "the event stream was refused" });
    }
  });
  return source;
}

// Saves a blob through the browser (fetch with the token, then a download link).
export async function download(digest, name) {
  const bytes = await blob(digest, name);
  const url = URL.createObjectURL(new Blob([bytes]));
  const a = document.createElement("a");
  a.href = url;
  a.download = name.split("/").pop();
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 60_000);
}

export const STATES = ["queued", "leased", "running", "succeeded", "failed", "cancelled"];

export function stateName(state) {
  return String(state || "").replace(/^JOB_STATE_/, "").toLowerCase();
}

// Re-queues a scene's failed and cancelled jobs: the scene's pipeline submitted again with the
// stages and parameters its jobs (and the jobs they depend on, fetched when another scene owns
// them) have, in the registry's order. Jobs are keyed by content, so succeeded ones are returned
// as they are and only failed / cancelled ones run again (as `instascene submit` again would).
export async function resubmitScene(scene, jobs) {
  const byId = new Map(jobs.map((j) => [j.id, j]));
  for (let pending = [...jobs]; pending.length;) {
    const next = [];
    for (const j of pending)
      for (const d of j.dependencies || [])
        if (!byId.has(d.job_id)) {
          const dep = await get(`/jobs/${encodeURIComponent(d.job_id)}`);
          byId.set(dep.id, dep);
          next.push(dep);
        }
    pending = next;
  }
  const submitted = [...byId.values()].filter((j) => !j.parent); // items come from their parent
  if (!submitted.length) throw new Error(`scene ${scene}: no jobs to resubmit`);
  const order = (await get("/stages")).stages.map((s) => s.kind);
  const stages = [...new Set(submitted.map((j) => j.kind))].sort((a, b) => order.indexOf(a) - order.indexOf(b));
  const parameters = {};
  for (const j of submitted) parameters[j.kind] = JSON.parse(j.parameters_json || "{}");
  return post("/pipelines", {
    scene,
    scene_manifest: submitted[0].scene_manifest,
    stages,
    parameters_json: JSON.stringify(parameters),
  });
}
