// End-to-end test of `jellysim view` in headless Chromium, driven by playwright-core
// (run by tests/integration/test_view.py):
//
//   node view_e2e.mjs NODE_MODULES CHROMIUM SCREENSHOT_DIR URL [URL ...]
//
// Each URL is a page address as `jellysim view` prints it (with the session's token). For each
// served result it loads the page and checks, through the page's controls and its read-only
// hook window.jellysimView: no console errors, page errors, failed requests or error answers
// (but 429, "busy", which the page waits out: counted as `busy`); the animation advances and
// plays through to the start again; pause (space bar) stops it; the play button toggles it; the
// scrub slider sets the frame and the picture changes with it; the tentacle slider changes the
// drawn count; the fluid toggle hides the particles. It fails (exit 1) at the first check that
// does not hold and prints one JSON line of observations per URL for the caller to check too,
// with the sizes of the /frames answers per part (`answers`).

import assert from "node:assert/strict";
import path from "node:path";
import { pathToFileURL } from "node:url";

const [modules, executablePath, screenshots, ...urls] = process.argv.slice(2);
const { chromium } = await import(pathToFileURL(path.join(modules, "playwright-core", "index.mjs")));

const TIMEOUT = 15000;
const hook = (page, name) => page.evaluate((key) => window.jellysimView[key], name);
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

// The metadata, asked for as the page asks (with the token, a 429 asked again a second later).
async function fetchMeta(url) {
  const headers = { "X-Jellysim-Token": new URL(url).searchParams.get("token") };
  for (;;) {
    const response = await fetch(new URL("/meta.json", url), { headers });
    if (response.status !== 429) {
      assert.equal(response.status, 200);
      return response.json();
    }
    await sleep(1000);
  }
}

async function check(browser, url, index) {
  const page = await browser.newPage({ viewport: { width: 800, height: 600 } });
  const problems = [];
  page.on("console", (message) => {
    // Chromium logs every error answer, the 429s the page waits out included.
    if (message.type() === "error" && message.text().includes("status of 429")) return;
    if (message.type() === "error" || message.type() === "warning") {
      problems.push(`console ${message.type()}: ${message.text()}`);
    }
  });
  page.on("pageerror", (error) => problems.push(`page error: ${error.message}`));
  page.on("requestfailed", (request) => {
    // A chunk the page dropped on purpose never fails; anything failing is a problem.
    problems.push(`request failed: ${request.url()} ${request.failure()?.errorText}`);
  });
  const answers = {}; // part -> sizes (bytes) of the /frames answers
  let busy = 0;
  page.on("response", (response) => {
    if (response.status() === 429) {
      busy++;
      return;
    }
    if (response.status() >= 400) problems.push(`HTTP ${response.status()}: ${response.url()}`);
    const address = new URL(response.url());
    if (address.pathname === "/frames") {
      const part = address.searchParams.get("part");
      (answers[part] ??= []).push(Number(response.headers()["content-length"]));
    }
  });

  await page.goto(url);
  await page.waitForFunction(() => window.jellysimView?.ready === true, null, { timeout: TIMEOUT });
  const meta = await fetchMeta(url);
  const observed = { url, frames: meta.frames };

  // Playing: the frame advances, and goes on through every chunk until it wraps to the start.
  const first = await hook(page, "frame");
  await page.waitForFunction((f) => window.jellysimView.frame !== f, first, { timeout: TIMEOUT });
  observed.advanced = true;
  let highest = -1;
  for (const deadline = Date.now() + 2 * TIMEOUT; ; await sleep(20)) {
    const frame = await hook(page, "frame");
    if (frame < highest) break;
    highest = Math.max(highest, frame);
    assert.ok(Date.now() < deadline, `playback stopped at frame ${highest}`);
  }
  observed.wrapped = highest; // the last frame drawn before the start again

  // Pause with the space bar: the frame stays put. Play and pause again with the button.
  await page.keyboard.press("Space");
  assert.equal(await hook(page, "playing"), false);
  const paused = await hook(page, "frame");
  await sleep(500);
  assert.equal(await hook(page, "frame"), paused, "the frame moved while paused");
  await page.click("#play");
  assert.equal(await hook(page, "playing"), true);
  await page.click("#play");
  assert.equal(await hook(page, "playing"), false);

  // Scrubbing sets the frame, and the picture changes with it.
  const canvas = page.locator("#view canvas");
  const before = await canvas.screenshot();
  const shown = await hook(page, "frame");
  const middle = Math.floor((meta.frames - 1) / 2);
  const target = shown === middle ? meta.frames - 1 : middle;
  await page.locator("#scrub").fill(String(target));
  await page.waitForFunction((f) => window.jellysimView.frame === f, target, { timeout: TIMEOUT });
  await sleep(100);
  observed.scrubbed = [shown, target];
  observed.pixelsChanged = !before.equals(await canvas.screenshot());
  assert.ok(observed.pixelsChanged, `frames ${shown} and ${target} look the same`);

  if (meta.tentacles.present) {
    // Drawn at `factor` per simulated tentacle; by group as data.js's drawnCount says (written
    // out again here: ribbons as simulated, rings T N, clusters of m (m - 1) N + 1 each).
    const drawn = (factor) =>
      (meta.tentacles.groups ?? [{ form: "thread", clusters: [meta.tentacles.simulated] }]).reduce(
        (sum, g) =>
          sum +
          (g.form === "ribbon"
            ? g.simulated
            : g.clusters.length === 1
              ? g.clusters[0] * factor
              : g.clusters.reduce((s, m) => s + (m - 1) * factor + 1, 0)),
        0,
      );
    assert.equal(await hook(page, "drawnTentacles"), drawn(meta.tentacles.interpolation));
    const factor = meta.tentacles.interpolation === 3 ? 2 : 3;
    await page.locator("#interpolation").fill(String(factor));
    await page.waitForFunction((n) => window.jellysimView.drawnTentacles === n, drawn(factor), {
      timeout: TIMEOUT,
    });
    observed.drawnTentacles = [drawn(meta.tentacles.interpolation), drawn(factor)];
  }

  if (meta.fluid.present) {
    const shown = await hook(page, "fluidPoints");
    assert.ok(shown > 0, "no fluid particles drawn");
    await page.locator("#fluid").uncheck();
    await page.waitForFunction(() => window.jellysimView.fluidPoints === 0, null, { timeout: TIMEOUT });
    await page.locator("#fluid").check();
    await page.waitForFunction(() => window.jellysimView.fluidPoints > 0, null, { timeout: TIMEOUT });
    observed.fluidPoints = [shown, 0, await hook(page, "fluidPoints")];
  }

  await sleep(200); // one more rendered frame after the last change
  observed.screenshot = path.join(screenshots, `view_${index}.png`);
  await page.screenshot({ path: observed.screenshot });
  assert.equal(await hook(page, "error"), null);
  assert.deepEqual(problems, []);
  await page.close();
  return { ...observed, answers, busy };
}

const browser = await chromium.launch({
  executablePath,
  // Headless Chromium without a GPU: WebGL through SwiftShader, which it allows only if asked.
  args: ["--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader"],
});
try {
  for (const [index, url] of urls.entries()) {
    console.log(JSON.stringify(await check(browser, url, index)));
  }
} finally {
  await browser.close();
}
