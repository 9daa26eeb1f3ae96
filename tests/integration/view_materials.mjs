// What three.js material each object of `jellysim view` gets, read in headless Chromium through
// the page's read-only hook window.jellysimView.materials (run by test_one_look_everywhere.py):
//
//   node view_materials.mjs NODE_MODULES CHROMIUM URL
//
// Prints one JSON line: the materials by object name, once the first frame is drawn.

import path from "node:path";
import { pathToFileURL } from "node:url";

const [modules, executablePath, url] = process.argv.slice(2);
const { chromium } = await import(pathToFileURL(path.join(modules, "playwright-core", "index.mjs")));

const browser = await chromium.launch({
  executablePath,
  // Headless Chromium without a GPU: WebGL through SwiftShader, as view_e2e.mjs launches it.
  args: ["--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader"],
});
try {
  const page = await browser.newPage({ viewport: { width: 320, height: 240 } });
  await page.goto(url);
  await page.waitForFunction(() => window.jellysimView.ready || window.jellysimView.error, null, {
    timeout: 60000,
  });
  const error = await page.evaluate(() => window.jellysimView.error);
  if (error) throw new Error(`the page failed: ${error}`);
  console.log(JSON.stringify(await page.evaluate(() => window.jellysimView.materials)));
} finally {
  await browser.close();
}
