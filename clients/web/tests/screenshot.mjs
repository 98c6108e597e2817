// One screenshot of the web UI's viewer with a scene's objects (scripts/demo.sh leaves it in its
// output folder): Debian's Chromium, headless, 1280x720; the first object selected.
// Usage: node screenshot.mjs GATEWAY_URL TOKEN SCENE OUT.png
import { chromium } from "playwright-core";

const [url, token, scene, out] = process.argv.slice(2);
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
  args: ["--headless=new", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
    "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run"],
});
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 720 } });
  await page.goto(`${url}/#token=${encodeURIComponent(token)}`);
  await page.goto(`${url}/#/viewer/${encodeURIComponent(scene)}`);
  await page.waitForSelector("#viewer-canvas[data-ready=true]", { timeout: 300_000 });
  await page.click("#object-list li button");
  await page.evaluate(() => new Promise((done) => { let n = 0; const tick = () => (++n < 10 ? requestAnimationFrame(tick) : done()); requestAnimationFrame(tick); }));
  await page.screenshot({ path: out });
  const stats = await page.evaluate(() => window.instasceneViewer);
  console.log(`${out}: ${stats.objects} objects, ${stats.gaussians} Gaussians, first frame after ${Math.round(stats.firstFrameMs)} ms`);
} finally {
  await browser.close();
}
