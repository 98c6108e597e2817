// viewer.js: the scene viewer. The background and every object are separate Spark splat meshes
// (three.js + @sparkjsdev/spark, WebGL2); the camera starts at the capture's first view. A click
// casts the camera ray and asks the Objects service which object it meets (the same index robots
// query), so what the page selects is what the API answers. The selected object is highlighted
// (the others dimmed) and a side panel shows its size, pose, observed vs completed share and its
// artefacts to download. A toggle swaps raw crops and completed objects where completion ran.
import * as THREE from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
import { SparkRenderer, SplatMesh } from "@sparkjsdev/spark";
import * as api from "./api.js";
import { parseGaussianPly } from "./ply.js";
import { el, showError } from "./ui.js";

const DIMMED = 0.25; // opacity of what is not selected (dense splats stay visible: also darkened)
const DIM_COLOR = new THREE.Color(0.3, 0.3, 0.3);
const FULL_COLOR = new THREE.Color(1, 1, 1);

function artefact(object, path) {
  return (object.artefacts || []).find((a) => a.path === path);
}

async function loadSplat(digest) {
  const parsed = parseGaussianPly(await api.blob(digest));
  const center = new THREE.Vector3();
  const scales = new THREE.Vector3();
  const quaternion = new THREE.Quaternion();
  const color = new THREE.Color();
  const mesh = new SplatMesh({
    constructSplats: (splats) => {
      for (let i = 0; i < parsed.count; ++i) {
        center.fromArray(parsed.centers, 3 * i);
        scales.fromArray(parsed.scales, 3 * i);
        quaternion.fromArray(parsed.quaternions, 4 * i);
        color.fromArray(parsed.colors, 3 * i);
        splats.pushSplat(center, scales, quaternion, parsed.opacities[i], color);
      }
    },
  });
  await mesh.initialized;
  mesh.userData.count = parsed.count;
  return mesh;
}

// The capture's first view as a three.js camera (OpenCV camera_from_world: x right, y down, z ahead).
function cameraFromView(view, aspect) {
  const rows = view.camera_from_world;
  const r = new THREE.Matrix3().set(
    rows[0][0], rows[0][1], rows[0][2],
    rows[1][0], rows[1][1], rows[1][2],
    rows[2][0], rows[2][1], rows[2][2]);
  const t = new THREE.Vector3(rows[0][3], rows[1][3], rows[2][3]);
  const rt = r.clone().transpose();
  const position = t.clone().applyMatrix3(rt).negate();
  const axis = (x, y, z) => new THREE.Vector3(x, y, z).applyMatrix3(rt);
  const fov = (2 * Math.atan(view.height / (2 * view.fy)) * 180) / Math.PI;
  const camera = new THREE.PerspectiveCamera(fov, aspect, 0.01, 1000);
  camera.position.copy(position);
  camera.up.copy(axis(0, -1, 0)); // OpenCV's y points down
  camera.lookAt(position.clone().add(axis(0, 0, 1)));
  return { camera, forward: axis(0, 0, 1) };
}

function formatVector(v, digits = 3) {
  return `(${[v.x, v.y, v.z].map((c) => Number(c || 0).toFixed(digits)).join(", ")})`;
}

export function render(main, sceneName) {
  const canvas = el("canvas", { id: "viewer-canvas", tabindex: "0", "aria-label": "3D view of the scene: click an object to select it" });
  const note = el("p", { id: "viewer-note" }, "Loading the scene…");
  const list = el("ul", { id: "object-list", class: "object-list", "aria-label": "Objects" });
  const panel = el("section", { id: "object-panel", class: "panel", "aria-live": "polite" }, el("p", {}, "Click an object (or pick one from the list)."));
  const completedToggle = el("input", { id: "show-completed", type: "checkbox", disabled: true });
  main.replaceChildren(el("section", { class: "viewer" },
    el("div", { class: "viewer-main" },
      el("h1", {}, `Viewer: ${sceneName}`),
      note,
      canvas),
    el("aside", { class: "viewer-side" },
      el("div", { class: "field inline" }, completedToggle, el("label", { for: "show-completed" }, "Show completed objects")),
      el("h2", {}, "Objects"),
      list,
      el("h2", {}, "Selected"),
      panel)));

  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
  const scene3 = new THREE.Scene();
  scene3.background = new THREE.Color(0x15171c);
  scene3.add(new SparkRenderer({ renderer }));
  let camera = new THREE.PerspectiveCamera(50, 16 / 9, 0.01, 1000);
  let controls = null;
  let stopped = false;
  const state = { objects: new Map(), background: null, selected: 0, completed: false };
  const stats = { ready: false, firstFrameMs: 0, gaussians: 0, objects: 0 };
  window.instasceneViewer = stats;
  const started = performance.now();

  function resize() {
    const width = canvas.clientWidth || 960;
    const height = canvas.clientHeight || 540;
    renderer.setSize(width, height, false);
    camera.aspect = width / height;
    camera.updateProjectionMatrix();
  }

  function shown(entry) {
    return state.completed && entry.completed ? entry.completed : entry.raw;
  }

  function dim(mesh, dimmed) {
    mesh.opacity = dimmed ? DIMMED : 1;
    mesh.recolor = dimmed ? DIM_COLOR : FULL_COLOR;
  }

  function applyHighlight() {
    for (const [id, entry] of state.objects) {
      for (const mesh of [entry.raw, entry.completed]) {
        if (!mesh) continue;
        mesh.visible = mesh === shown(entry);
        dim(mesh, state.selected && state.selected !== id);
      }
    }
    if (state.background) dim(state.background, state.selected);
    for (const item of list.children)
      item.querySelector("button").setAttribute("aria-pressed", String(Number(item.dataset.id) === state.selected));
  }

  function showPanel(object) {
    if (!object) {
      panel.replaceChildren(el("p", {}, "Nothing selected."));
      return;
    }
    const metres = object.units === "metres";
    const e = object.extent || {};
    const size = metres
      ? `${(e.x * 100).toFixed(1)} × ${(e.y * 100).toFixed(1)} × ${(e.z * 100).toFixed(1)} cm`
      : `${formatVector(e)} scene units (the scene has no metric scale)`;
    const pose = object.world_from_object || {};
    const r = pose;
    const downloads = (object.artefacts || []).filter((a) => /\.(glb|ply|urdf|xml|stl|drc|json)$/.test(a.path));
    panel.replaceChildren(
      el("h3", { id: "selected-title" }, `Object ${object.id}`),
      el("dl", {},
        el("dt", {}, "Size"), el("dd", { id: "selected-size" }, size),
        el("dt", {}, "Position"), el("dd", {}, `${formatVector(pose.translation || {})} ${metres ? "m" : ""}`),
        el("dt", {}, "Rotation (x, y, z, w)"), el("dd", {}, [r.qx, r.qy, r.qz, r.qw].map((q) => Number(q || 0).toFixed(3)).join(", ")),
        el("dt", {}, "Completion"), el("dd", {}, object.completion || ""),
        el("dt", {}, "Observed / completed"), el("dd", { id: "selected-share" }, `${(100 * (1 - (object.completed_share || 0))).toFixed(0)} % / ${(100 * (object.completed_share || 0)).toFixed(0)} %`),
        el("dt", {}, "Source"), el("dd", {}, object.source)),
      el("h4", {}, "Downloads"),
      el("ul", { class: "downloads" }, downloads.map((a) => el("li", {},
        el("button", {
          type: "button",
          "data-artefact": a.path,
          onclick: () => api.download(a.digest, `object-${object.id}-${a.path.replaceAll("/", "-")}`).catch((err) => showError(note, err)),
        }, `Download ${a.path}`)))));
  }

  function select(id) {
    state.selected = id;
    stats.picks = (stats.picks || 0) + 1;
    applyHighlight();
    showPanel(id ? state.objects.get(id)?.object : null);
    stats.selected = id;
  }

  async function pick(event) {
    const rect = canvas.getBoundingClientRect();
    const ndc = new THREE.Vector2(((event.clientX - rect.left) / rect.width) * 2 - 1, -((event.clientY - rect.top) / rect.height) * 2 + 1);
    const raycaster = new THREE.Raycaster();
    raycaster.setFromCamera(ndc, camera);
    const { origin: o, direction: d } = raycaster.ray;
    const ray = [o.x, o.y, o.z, d.x, d.y, d.z].map((v) => v.toFixed(6)).join(",");
    try {
      const object = await api.get(`/scenes/${encodeURIComponent(sceneName)}/object?ray=${ray}`);
      select(object.id);
    } catch (e) {
      if (e.status === "NOT_FOUND") select(0);
      else showError(note, e);
    }
  }

  let down = null;
  canvas.addEventListener("pointerdown", (e) => { down = [e.clientX, e.clientY]; });
  canvas.addEventListener("pointerup", (e) => {
    if (down && Math.hypot(e.clientX - down[0], e.clientY - down[1]) < 4) pick(e); // a click, not a drag
    down = null;
  });
  canvas.addEventListener("keydown", (e) => {
    if (e.key === "Escape") select(0);
  });
  completedToggle.addEventListener("change", () => {
    state.completed = completedToggle.checked;
    applyHighlight();
  });

  (async () => {
    const info = await api.get(`/scenes/${encodeURIComponent(sceneName)}`);
    const segment = (info.outputs || []).find((o) => o.kind === "segment");
    if (!segment) throw new Error("no segmentation yet: the viewer opens once the segment stage succeeded");
    const sceneManifest = await api.blobJson(info.scene_manifest);
    const sceneJson = await api.blobJson(api.parseDigest(sceneManifest.files["scene.json"]));
    const segmentManifest = await api.blobJson(segment.output_manifest);
    const objects = [];
    let page = "";
    do {
      const answer = await api.get(`/scenes/${encodeURIComponent(sceneName)}/objects?limit=500${page ? `&page_token=${page}` : ""}`);
      objects.push(...(answer.objects || []));
      page = answer.next_page_token || "";
    } while (page);
    const view = sceneJson.views[0];
    ({ camera } = cameraFromView(view, 16 / 9));
    resize();
    const loads = [];
    const background = segmentManifest.files["instances/background.ply"];
    if (background) loads.push(loadSplat(api.parseDigest(background)).then((m) => { state.background = m; }));
    for (const object of objects) {
      const entry = { object, raw: null, completed: null };
      state.objects.set(object.id, entry);
      const raw = artefact(object, "splat.ply");
      const completed = artefact(object, "object.ply");
      if (raw) loads.push(loadSplat(raw.digest).then((m) => { entry.raw = m; }));
      if (completed) loads.push(loadSplat(completed.digest).then((m) => { entry.completed = m; }));
    }
    await Promise.all(loads);
    if (stopped) return;
    stats.loadedMs = performance.now() - started; // downloaded, parsed and handed to Spark
    const all = [state.background, ...[...state.objects.values()].flatMap((e) => [e.raw, e.completed])].filter(Boolean);
    for (const mesh of all) scene3.add(mesh);
    stats.gaussians = [state.background, ...[...state.objects.values()].map((e) => e.raw)].filter(Boolean).reduce((n, m) => n + m.userData.count, 0);
    stats.objects = objects.length;
    completedToggle.disabled = ![...state.objects.values()].some((e) => e.completed);
    // Orbit around the objects' centre, seen from the first view.
    const centre = new THREE.Vector3();
    for (const o of objects) centre.add(new THREE.Vector3(o.world_from_object.translation.x, o.world_from_object.translation.y, o.world_from_object.translation.z).multiplyScalar(1 / (o.meters_per_unit || 1)));
    if (objects.length) centre.multiplyScalar(1 / objects.length);
    controls = new OrbitControls(camera, canvas);
    controls.target.copy(centre);
    controls.update();
    list.replaceChildren(...objects.map((o) => el("li", { "data-id": o.id },
      el("button", { type: "button", "aria-pressed": "false", onclick: () => select(o.id) }, `Object ${o.id} · ${o.completion}`))));
    note.textContent = `${objects.length} objects, ${stats.gaussians.toLocaleString()} Gaussians.`;
    applyHighlight();
    // Time to the first frame that shows splats (Spark sorts and uploads them in the background,
    // so the first render calls may draw the background colour only): a 32x18 sample per frame
    // until one differs from the clear colour.
    const probe = document.createElement("canvas");
    probe.width = 32;
    probe.height = 18;
    const probeContext = probe.getContext("2d", { willReadFrequently: true });
    renderer.setAnimationLoop(() => {
      controls.update();
      renderer.render(scene3, camera);
      if (!stats.ready) {
        probeContext.drawImage(canvas, 0, 0, probe.width, probe.height);
        const data = probeContext.getImageData(0, 0, probe.width, probe.height).data;
        let lit = 0;
        for (let i = 0; i < data.length; i += 4)
          if (Math.abs(data[i] - 0x15) + Math.abs(data[i + 1] - 0x17) + Math.abs(data[i + 2] - 0x1c) > 30) lit += 1;
        if (lit > 0.01 * probe.width * probe.height) {
          stats.firstFrameMs = performance.now() - started;
          stats.ready = true;
          canvas.dataset.ready = "true";
        }
      }
    });
    // For tests and integrators: where on the canvas an object's centre lies (CSS pixels).
    stats.project = (id) => {
      const o = state.objects.get(id)?.object;
      if (!o) return null;
      const s = 1 / (o.meters_per_unit || 1);
      const t = o.world_from_object.translation;
      const p = new THREE.Vector3(t.x * s, t.y * s, t.z * s).project(camera);
      const rect = canvas.getBoundingClientRect();
      return { x: rect.left + ((p.x + 1) / 2) * rect.width, y: rect.top + ((1 - p.y) / 2) * rect.height };
    };
  })().catch((e) => showError(note, e));

  window.addEventListener("resize", resize);
  return () => {
    stopped = true;
    window.removeEventListener("resize", resize);
    renderer.setAnimationLoop(null);
    controls?.dispose();
    renderer.dispose();
  };
}
