// upload.js: a scene folder (or a zip of one) from the user's disk into the store, then the
// pipeline submitted. Every file is digested here (streaming SHA-256, @noble/hashes: works on plain
// HTTP too, where WebCrypto is unavailable, and never holds a large file whole); the gateway keeps
// the files scene.json references and says which the store lacks; only those are sent, in chunks
// with Upload-Offset, so an interrupted upload resumes where the store's committed size says.
import { sha256 } from "@noble/hashes/sha2.js";
import { bytesToHex } from "@noble/hashes/utils.js";
import { unzipSync } from "fflate";
import * as api from "./api.js";
import { announce, el, field, showError } from "./ui.js";

const CHUNK = 4 << 20; // bytes per PUT (the gateway's body limit is 8 MiB)
const MAX_ZIP_BYTES = 2 * 1024 ** 3; // unzipped in memory: a capture larger than this goes as a folder

// Files as {path, size, read(start, end) -> Promise<Uint8Array>}, paths relative to the folder
// holding scene.json.
function fromFileList(list) {
  const files = [...list].map((f) => ({
    path: f.webkitRelativePath || f.name,
    size: f.size,
    read: async (start, end) => new Uint8Array(await f.slice(start, end).arrayBuffer()),
  }));
  return relativeToScene(files);
}

async function fromZip(file) {
  if (file.size > MAX_ZIP_BYTES) throw new Error(`${file.name}: larger than 2 GiB; upload the folder instead`);
  const entries = unzipSync(new Uint8Array(await file.arrayBuffer()));
  const files = Object.entries(entries)
    .filter(([path]) => !path.endsWith("/"))
    .map(([path, bytes]) => ({ path, size: bytes.length, read: async (s, e) => bytes.subarray(s, e) }));
  return relativeToScene(files);
}

function relativeToScene(files) {
  const sceneJson = files
    .filter((f) => f.path === "scene.json" || f.path.endsWith("/scene.json"))
    .sort((a, b) => a.path.length - b.path.length)[0];
  if (!sceneJson) throw new Error("no scene.json in the folder (or zip) given");
  const prefix = sceneJson.path.slice(0, sceneJson.path.length - "scene.json".length);
  return files
    .filter((f) => f.path.startsWith(prefix))
    .map((f) => ({ ...f, path: f.path.slice(prefix.length) }));
}

async function digest(file, onBytes) {
  const h = sha256.create();
  for (let start = 0; start < file.size; start += CHUNK) {
    const bytes = await file.read(start, Math.min(file.size, start + CHUNK));
    h.update(bytes);
    onBytes(bytes.length);
  }
  return { hash: bytesToHex(h.digest()), size_bytes: file.size };
}

// Sends what the store lacks of one blob, resuming at its committed size; retries a chunk that
// failed on the network (not one the gateway refused) a few times.
async function uploadBlob(file, d, onBytes) {
  const status = await api.get(`/blobs/${d.hash}/${d.size_bytes}/status`);
  let offset = Number(status.committed_size || 0);
  if (status.complete) return onBytes(file.size);
  onBytes(offset);
  if (file.size === 0) return api.putChunk(d, 0, new Uint8Array());
  let failures = 0;
  while (offset < file.size) {
    const end = Math.min(file.size, offset + CHUNK);
    try {
      await api.putChunk(d, offset, await file.read(offset, end));
      onBytes(end - offset);
      offset = end;
      failures = 0;
    } catch (e) {
      if (e instanceof api.ApiError || ++failures > 5) throw e;
      const s = await api.get(`/blobs/${d.hash}/${d.size_bytes}/status`);
      onBytes(Number(s.committed_size || 0) - offset);
      offset = Number(s.committed_size || 0);
    }
  }
}

export function render(main, navigate) {
  const name = el("input", { id: "scene-name", name: "scene", required: true, pattern: "[A-Za-z0-9][A-Za-z0-9._\\-]*", placeholder: "e.g. kitchen-01" });
  const folder = el("input", { id: "folder", type: "file", webkitdirectory: true, multiple: true });
  const zip = el("input", { id: "zip", type: "file", accept: ".zip,application/zip" });
  const stages = el("input", { id: "stages", placeholder: "every stage" });
  const bar = el("progress", { id: "upload-progress", max: 1, value: 0 });
  const label = el("p", { id: "upload-label" }, "Choose a folder or a zip.");
  const submit = el("button", { type: "submit" }, "Upload and run");
  const form = el("form", { class: "card", "aria-labelledby": "upload-title" },
    el("h1", { id: "upload-title" }, "Upload a capture"),
    el("p", {}, "A scene folder with scene.json, the splat, images and masks (instascene import writes one). Only files the server lacks are sent; an interrupted upload resumes when you start it again."),
    field("Scene name", name),
    field("Scene folder", folder),
    field("…or a zip of it", zip),
    field("Stages (comma-separated, optional)", stages),
    submit,
    el("div", { class: "progress" }, el("label", { for: "upload-progress" }, "Progress"), bar),
    label);
  main.replaceChildren(form);
  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    submit.disabled = true;
    try {
      let files;
      if (zip.files.length) files = await fromZip(zip.files[0]);
      else if (folder.files.length) files = fromFileList(folder.files);
      else throw new Error("choose a scene folder or a zip first");
      const total = files.reduce((n, f) => n + f.size, 0);
      let hashed = 0;
      label.textContent = `Digesting ${files.length} files…`;
      const digests = {};
      for (const f of files) {
        digests[f.path] = await digest(f, (n) => {
          hashed += n;
          bar.value = total ? (0.2 * hashed) / total : 0.2;
        });
      }
      const sceneJson = files.find((f) => f.path === "scene.json");
      await uploadBlob(sceneJson, digests["scene.json"], () => {});
      const plan = await api.post("/scene-manifests", { files: digests });
      const missing = plan.missing.map((p) => files.find((f) => f.path === p));
      const bytes = Number(plan.missing_bytes) || 0;
      let sent = 0;
      label.textContent = `Uploading ${missing.length} of ${Object.keys(plan.files).length} files (${(bytes / 1e6).toFixed(1)} MB)…`;
      for (const f of missing) {
        await uploadBlob(f, digests[f.path], (n) => {
          sent += n;
          bar.value = 0.2 + (bytes ? (0.8 * sent) / bytes : 0.8);
        });
      }
      bar.value = 1;
      const request = { scene: name.value.trim(), scene_manifest: plan.scene_manifest };
      const wanted = stages.value.split(",").map((s) => s.trim()).filter(Boolean);
      if (wanted.length) request.stages = wanted;
      const submitted = await api.post("/pipelines", request);
      // Jobs are keyed by the capture's content: the same capture under another name gets the
      // jobs it already has (nothing is computed twice), filed under the first name.
      const scene = submitted.jobs[0]?.scene || request.scene;
      const created = (submitted.created || []).filter(Boolean).length;
      announce(scene === request.scene
        ? `Submitted ${submitted.jobs.length} jobs (${created} new).`
        : `This capture was already submitted as scene ${scene}: showing its jobs (${created} new).`);
      navigate(`#/scenes/${encodeURIComponent(scene)}`);
    } catch (e) {
      showError(label, e);
    } finally {
      submit.disabled = false;
    }
  });
}
