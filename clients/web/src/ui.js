// ui.js: small DOM helpers shared by the pages (no framework: the pages are few and plain).

// el("button", {type: "submit", onclick: f}, "Save", child...)
export function el(tag, attributes = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attributes)) {
    if (value === undefined || value === null || value === false) continue;
    if (key.startsWith("on")) node.addEventListener(key.slice(2), value);
    else if (value === true) node.setAttribute(key, "");
    else node.setAttribute(key, String(value));
  }
  node.append(...children.flat().filter((c) => c !== undefined && c !== null));
  return node;
}

// A labelled form field (the label names the control for screen readers).
export function field(text, control) {
  if (!control.id) control.id = `f-${Math.random().toString(36).slice(2)}`;
  return el("div", { class: "field" }, el("label", { for: control.id }, text), control);
}

export function showError(target, error) {
  target.textContent = error?.message || String(error);
  target.classList.add("error");
  target.setAttribute("role", "alert");
}

export function announce(text) {
  document.getElementById("status").textContent = text;
}

export function formatSeconds(s) {
  if (!(s >= 0)) return "";
  if (s < 60) return `${s.toFixed(0)} s`;
  if (s < 3600) return `${(s / 60).toFixed(1)} min`;
  return `${(s / 3600).toFixed(1)} h`;
}

export function formatTime(unixMs) {
  const ms = Number(unixMs);
  return ms ? new Date(ms).toLocaleTimeString() : "";
}

// A small SVG line chart of [t, value] samples (no chart library needed for a sparkline).
export function sparkline(samples, { width = 240, height = 48, label = "" } = {}) {
  const svg = document.createElementNS("http://www.w3.org/2000/svg", "svg");
  svg.setAttribute("viewBox", `0 0 ${width} ${height}`);
  svg.setAttribute("width", width);
  svg.setAttribute("height", height);
  svg.setAttribute("role", "img");
  svg.setAttribute("aria-label", label);
  if (samples.length >= 2) {
    const t0 = samples[0][0];
    const t1 = samples[samples.length - 1][0];
    const vmax = Math.max(1e-9, ...samples.map((s) => s[1]));
    const points = samples
      .map(([t, v]) => `${(((t - t0) / Math.max(1, t1 - t0)) * (width - 2) + 1).toFixed(1)},${(height - 1 - (v / vmax) * (height - 2)).toFixed(1)}`)
      .join(" ");
    const line = document.createElementNS("http://www.w3.org/2000/svg", "polyline");
    line.setAttribute("points", points);
    line.setAttribute("fill", "none");
    line.setAttribute("stroke", "currentColor");
    line.setAttribute("stroke-width", "1.5");
    svg.append(line);
  }
  return svg;
}
