// End-to-end test of `jellysim view` in headless Chromium, driven by playwright-core
// (run by tests/integration/test_view.py):
//
//   node view_e2e.mjs NODE_MODULES CHROMIUM SCREENSHOT_DIR URL [URL ...]
//
// For each served result it loads the page and checks, through the page's controls and its
// read-only hook window.jellysimView: no console errors, page errors or failed requests; the
// animation advances; pause (space bar) stops it; the play button toggles it; the scrub slider
// sets the frame and the picture changes with it; the tentacle slider changes the drawn count;
// the fluid toggle hides the particles. It fails (exit 1) at the first check that does not hold
// and prints one JSON line of observations per URL for the caller to check too.

import assert from "node:assert/strict";
import path from "node:path";
import { pathToFileURL } from "node:url";

const [modules, executablePath, screenshots, ...urls] = process.argv.slice(2);
const { chromium } = await import(pathToFileURL(path.join(modules, "playwright-core", "index.mjs")));

const TIMEOUT = 15000;
const hook = (page, name) => page.evaluate((key) => window.jellysimView[key], name);
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

async function check(browser, url, index) {
  const page = await browser.newPage({ viewport: { width: 800, height: 600 } });
  const problems = [];
  page.on("console", (message) => {
    if (message.type() === "error" || message.type() === "warning") {
      problems.push(`console ${message.type()}: ${message.text()}`);
    }
  });
  page.on("pageerror", (error) => problems.push(`page error: ${error.message}`));
  page.on("requestfailed", (request) => {
    // A chunk the page dropped on purpose never fails; anything failing is a problem.
    problems.push(`request failed: ${request.url()} ${request.failure()?.errorText}`);
  });
  page.on("response", (response) => {
    if (response.status() >= 400) problems.push(`HTTP ${response.status()}: ${response.url()}`);
  });

  const meta = await (await fetch(new URL("meta.json", url))).json();
  await page.goto(url);
  await page.waitForFunction(() => window.jellysimView?.ready === true, null, { timeout: TIMEOUT });
  const observed = { url, frames: meta.frames };

  // Playing: the frame advances.
  const first = await hook(page, "frame");
  await page.waitForFunction((f) => window.jellysimView.frame !== f, first, { timeout: TIMEOUT });
  observed.advanced = true;

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
    const simulated = meta.tentacles.simulated;
    assert.equal(await hook(page, "drawnTentacles"), simulated * meta.tentacles.interpolation);
    const factor = meta.tentacles.interpolation === 3 ? 2 : 3;
    await page.locator("#interpolation").fill(String(factor));
    await page.waitForFunction((n) => window.jellysimView.drawnTentacles === n, simulated * factor, {
      timeout: TIMEOUT,
    });
    observed.drawnTentacles = [simulated * meta.tentacles.interpolation, simulated * factor];
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
  return observed;
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
