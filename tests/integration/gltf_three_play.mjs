// Load a .glb with three.js's GLTFLoader and play its first animation with an AnimationMixer.
// Usage: node gltf_three_play.mjs NODE_MODULES FILE TIME...
// Prints JSON: the clip's duration (s), the number of meshes and point clouds, and per TIME, per
// mesh (by name), the morph targets (by name, three.js's morphTargetDictionary) whose influence
// is not zero, and whether the mesh is shown (its scale not zero).
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
const drawn = [];
gltf.scene.traverse((object) => {
  if (object.isMesh || object.isPoints) drawn.push(object);
});
const shown = times.map((time) => {
  mixer.setTime(Number(time));
  const state = {};
  for (const object of drawn) {
    const names = Object.entries(object.morphTargetDictionary || {});
    const on = names.filter(([, k]) => object.morphTargetInfluences[k] !== 0).map(([n]) => n);
    state[object.name] = { targets: on, shown: object.parent.scale.x !== 0 && object.scale.x !== 0 };
  }
  return state;
});
process.stdout.write(JSON.stringify({ duration: clip.duration, meshes: drawn.length, shown }));
