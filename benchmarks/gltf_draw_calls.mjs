// What three.js draws of a glTF export, in headless Chromium (WebGL through SwiftShader):
// loads each .glb with GLTFLoader, plays its first animation with an AnimationMixer to the
// middle of its first, middle and last frame, renders a 320 x 240 picture and reports three.js's
// own counters (renderer.info: draw calls, triangles, points), the GPU's uniform limit and
// whether anything but the background was drawn. Used for docs/exports.md's numbers.
//
//   node benchmarks/gltf_draw_calls.mjs NODE_MODULES CHROMIUM FILE.glb [FILE.glb ...]
//
// Prints one JSON line per file. Needs web/node_modules (make web: three, playwright-core) and
// Chromium (make chromium).

import { createReadStream, statSync } from "node:fs";
import http from "node:http";
import path from "node:path";
import { pathToFileURL } from "node:url";

const [modules, executablePath, ...files] = process.argv.slice(2);
const { chromium } = await import(pathToFileURL(path.join(modules, "playwright-core", "index.mjs")));

const PAGE = `<!doctype html><html><body>
<script type="importmap">{"imports": {"three": "/modules/three/build/three.module.js",
"three/addons/": "/modules/three/examples/jsm/"}}</script>
<script type="module">
import * as THREE from "three";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
window.measure = async (url) => {
  const renderer = new THREE.WebGLRenderer({ antialias: false });
  renderer.setSize(320, 240);
  document.body.appendChild(renderer.domElement);
  const gltf = await new GLTFLoader().loadAsync(url);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0, 0, 0);
  scene.add(gltf.scene, new THREE.AmbientLight(0xffffff, 1), new THREE.DirectionalLight(0xffffff, 2));
  const box = new THREE.Box3().setFromObject(gltf.scene);
  const centre = box.getCenter(new THREE.Vector3());
  const size = box.getSize(new THREE.Vector3()).length();
  const camera = new THREE.PerspectiveCamera(40, 320 / 240, size / 100, size * 10);
  camera.position.set(centre.x, centre.y, centre.z + 1.5 * size);
  camera.lookAt(centre);
  const clip = gltf.animations[0];
  const mixer = new THREE.AnimationMixer(gltf.scene);
  if (clip) mixer.clipAction(clip).play();
  const gl = renderer.getContext();
  const extras = gltf.parser.json.asset.extras || {};
  const step = (extras.frame_step || 1) / (extras.fps || 1);
  const first = (extras.first_frame || 0) / (extras.fps || 1);
  const last = (extras.last_frame || 0) / (extras.fps || 1);
  const samples = [];
  for (const time of [first, (first + last) / 2, last].map((t) => t + step / 2)) {
    mixer.setTime(time);
    renderer.info.reset();
    renderer.info.autoReset = false;
    renderer.render(scene, camera);
    const pixels = new Uint8Array(320 * 240 * 4);
    gl.readPixels(0, 0, 320, 240, gl.RGBA, gl.UNSIGNED_BYTE, pixels);
    let drawn = 0;
    for (let i = 0; i < pixels.length; i += 4) if (pixels[i] + pixels[i + 1] + pixels[i + 2] > 0) drawn += 1;
    const { calls, triangles, points } = renderer.info.render;
    samples.push({ time, calls, triangles, points, drawn_fraction: drawn / (320 * 240) });
  }
  let meshes = 0;
  let morphTargets = 0;
  gltf.scene.traverse((object) => {
    if (object.isMesh || object.isPoints) {
      meshes += 1;
      morphTargets = Math.max(morphTargets, (object.morphTargetInfluences || []).length);
    }
  });
  return {
    duration: clip ? clip.duration : 0,
    meshes,
    morph_targets: morphTargets,
    max_vertex_uniform_vectors: gl.getParameter(gl.MAX_VERTEX_UNIFORM_VECTORS),
    samples,
  };
};
window.ready = true;
</script></body></html>`;

const server = http.createServer((request, response) => {
  const url = new URL(request.url, "http://localhost");
  let file = null;
  if (url.pathname === "/favicon.ico") {
    response.writeHead(204);
    response.end();
    return;
  }
  if (url.pathname === "/") {
    response.writeHead(200, { "Content-Type": "text/html" });
    response.end(PAGE);
    return;
  }
  if (url.pathname.startsWith("/modules/")) file = path.join(modules, url.pathname.slice(9));
  if (url.pathname.startsWith("/file/")) file = files[Number(url.pathname.slice(6))];
  if (file === null) {
    response.writeHead(404);
    response.end();
    return;
  }
  const type = file.endsWith(".js") ? "text/javascript" : "application/octet-stream";
  response.writeHead(200, { "Content-Type": type, "Content-Length": statSync(file).size });
  createReadStream(file).pipe(response);
});
await new Promise((resolve) => server.listen(0, "127.0.0.1", resolve));
const port = server.address().port;

const browser = await chromium.launch({
  executablePath,
  args: ["--no-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader"],
});
try {
  const page = await browser.newPage();
  const errors = [];
  page.on("console", (message) => {
    if (message.type() === "error") errors.push(message.text());
  });
  page.on("pageerror", (error) => errors.push(String(error)));
  await page.goto(`http://127.0.0.1:${port}/`);
  await page.waitForFunction(() => window.ready === true);
  for (const [index, file] of files.entries()) {
    const result = await page.evaluate((url) => window.measure(url), `/file/${index}`);
    const bytes = statSync(file).size;
    process.stdout.write(JSON.stringify({ file: path.basename(file), bytes, ...result, errors }) + "\n");
  }
} finally {
  await browser.close();
  server.close();
}
