// Measurements of the web UI in Debian's Chromium (scripts/bench_web.sh; docs/PERFORMANCE.md):
//   - time to the first frame that shows splats, from the viewer page's start (downloads of every
//     splat through the gateway, parsing, Spark's upload and sort), RUNS times with a fresh browser
//     context each (no HTTP cache);
//   - Server-Sent Events latency: the scene page of a pipeline submitted just before, from each
//     job update on the scheduler to its arrival in the page (measured first, while it runs).
// Usage: node bench_viewer.mjs GATEWAY_URL TOKEN VIEW_SCENE RUNS LIVE_SCENE
// Prints one JSON line.
import { chromium } from "playwright-core";

const [url, token, viewScene, runs, liveScene] = process.argv.slice(2);
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  args: ["--headless=new", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
    "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run"],
});
const median = (a) => { const s = [...a].sort((x, y) => x - y); return s.length ? s[Math.floor((s.length - 1) / 2)] : null; };
const quantile = (a, q) => { const s = [...a].sort((x, y) => x - y); return s.length ? s[Math.min(s.length - 1, Math.floor(q * s.length))] : null; };
const liveContext = await browser.newContext();
const livePage = await liveContext.newPage();
await livePage.goto(`${url}/#token=${encodeURIComponent(token)}`);
await livePage.goto(`${url}/#/scenes/${liveScene}`);
await livePage.waitForSelector("#scene-summary[data-done=true]", { timeout: 600_000 });
const latencies = await livePage.evaluate(() => window.instasceneEventLatencies);
await liveContext.close();
const frames = [];
const loaded = [];
const fps = [];
let gaussians = 0;
for (let i = 0; i < Number(runs); ++i) {
  const context = await browser.newContext({ viewport: { width: 1280, height: 720 } });
  const page = await context.newPage();
  await page.goto(`${url}/#token=${encodeURIComponent(token)}`);
  await page.goto(`${url}/#/viewer/${viewScene}`);
  await page.waitForSelector("#viewer-canvas[data-ready=true]", { timeout: 300_000 });
  const stats = await page.evaluate(() => ({ ms: window.instasceneViewer.firstFrameMs, loaded: window.instasceneViewer.loadedMs, gaussians: window.instasceneViewer.gaussians }));
  frames.push(stats.ms);
  loaded.push(stats.loaded);
  // Steady state: frames per second over 3 s once the splats are drawn.
  fps.push(await page.evaluate(() => new Promise((done) => {
    let n = 0;
    const t0 = performance.now();
    const tick = () => { n += 1; if (performance.now() - t0 < 3000) requestAnimationFrame(tick); else done((n * 1000) / (performance.now() - t0)); };
    requestAnimationFrame(tick);
  })));
  gaussians = stats.gaussians;
  await context.close();
}
await browser.close();
console.log(JSON.stringify({
  viewer_gaussians: gaussians, viewer_runs: frames.length, viewer_first_frame_ms_median: Math.round(median(frames)),
  viewer_first_frame_ms: frames.map(Math.round), viewer_loaded_ms_median: Math.round(median(loaded)),
  viewer_fps_median: Math.round(10 * median(fps)) / 10,
  sse_events: latencies.length, sse_latency_ms_median: median(latencies), sse_latency_ms_p95: quantile(latencies, 0.95),
  sse_latency_ms_max: latencies.length ? Math.max(...latencies) : null,
}));
