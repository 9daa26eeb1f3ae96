// Load a .glb with three.js's GLTFLoader and play its first animation with an AnimationMixer.
// Usage: node gltf_three_play.mjs NODE_MODULES FILE TIME...
// Prints JSON: the clip's duration (s), the number of meshes, and per TIME the names of the
// frame nodes (children of the scene's root node) whose scale is not zero.
import { readFile } from "node:fs/promises";
import path from "node:path";
import { pathToFileURL } from "node:url";

const [modules, file, ...times] = process.argv.slice(2);
const load = (relative) => import(pathToFileURL(path.resolve(modules, relative)).href);
const THREE = await load("three/build/three.module.js");
const { GLTFLoader } = await load("three/examples/jsm/loaders/GLTFLoader.js");

const bytes = await readFile(file);
const data = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
const gltf = await new GLTFLoader().parseAsync(data, "");
const clip = gltf.animations[0];
const mixer = new THREE.AnimationMixer(gltf.scene);
mixer.clipAction(clip).play();
let meshes = 0;
gltf.scene.traverse((object) => {
  if (object.isMesh || object.isPoints) meshes += 1;
});
const frames = gltf.scene.children[0].children;
const shown = times.map((time) => {
  mixer.setTime(Number(time));
  return frames.filter((node) => node.scale.x !== 0).map((node) => node.name);
});
process.stdout.write(JSON.stringify({ duration: clip.duration, meshes, shown }));
