// `jellysim view`: plays a result with three.js (docs/viewer.md). World coordinates are the
// result's: SI units, z up (the camera's up is +z); a 2-D fluid arrives as (x, 0, y).

import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { FrameStore, drawnCount, fetchBellFaces, fetchFluidKinds, fetchMeta } from "./data.js";

const VIEW_DIRECTION = new THREE.Vector3(0, 1, -0.25).normalize(); // as jellysim render's camera
const KIND_COLORS = [
  [0.25, 0.55, 0.95], // fluid
  [0.45, 0.45, 0.45], // wall
  [0.22, 0.22, 0.22], // dummy
];

const $ = (id) => document.getElementById(id);

// What the page shows; read (never written) by tests through window.jellysimView.
const state = {
  ready: false, // the first frame is drawn
  frame: -1, // the frame drawn
  position: 0, // playback position in frames (fractional)
  playing: true,
  speed: 1,
  interpolation: 1,
  drawnTentacles: 0,
  fluidPoints: 0, // fluid particles drawn (0 while hidden)
  error: null,
};

// The documented test hook (docs/viewer.md, "Test hook"): read-only getters.
window.jellysimView = Object.freeze({
  get ready() { return state.ready; },
  get frame() { return state.frame; },
  get playing() { return state.playing; },
  get speed() { return state.speed; },
  get interpolation() { return state.interpolation; },
  get drawnTentacles() { return state.drawnTentacles; },
  get fluidPoints() { return state.fluidPoints; },
  get error() { return state.error; },
  get materials() { return describeMaterials(); },
});

// What each drawn object's three.js material is (the hook's `materials`): by object name.
const drawnObjects = [];
function describeMaterials() {
  const rgb = (color) => (color ? color.toArray() : null); // linear, as three.js holds them
  return Object.fromEntries(
    drawnObjects.map((object) => {
      const m = object.material;
      return [
        object.name,
        {
          type: m.type,
          color: rgb(m.color),
          emissive: rgb(m.emissive),
          opacity: m.opacity,
          transparent: m.transparent,
          shininess: m.shininess ?? null,
        },
      ];
    }),
  );
}

function showError(error) {
  state.error = String(error.message ?? error);
  $("status").textContent = state.error;
  $("status").classList.add("error");
  console.error(`jellysim view: ${state.error}`);
}

const linear = (rgb) => new THREE.Color().setRGB(rgb[0], rgb[1], rgb[2], THREE.LinearSRGBColorSpace);

// The bell's material: Phong lighting of the shared material's colour, glow and opacity, with
// the Fresnel-like rim and radial stripes of jellysim.render.materials (bell_transmit,
// stripe_weight) added to the shader, as POV-Ray and the preview draw them. The stripes turn
// about the bell's vertical axis through uniform bellCentre (set each frame).
function bellMaterial(look) {
  const t = look.bell_transparency;
  const uniforms = {
    rimFace: { value: t + (1 - t) * look.rim }, // transmit face-on
    rimEdge: { value: t * (1 - look.rim) }, // transmit at the silhouette
    rimLighten: { value: look.rim },
    stripes: { value: look.stripes },
    stripeColor: { value: linear(look.stripe_color) },
    stripeTransmit: { value: look.stripe_transmit },
    bellCentre: { value: new THREE.Vector3() },
  };
  const material = new THREE.MeshPhongMaterial({
    color: linear(look.bell_color),
    emissive: linear(look.bell_emissive),
    transparent: true,
    opacity: 1 - t,
    side: THREE.DoubleSide,
    depthWrite: false,
    shininess: look.bell_shininess,
  });
  material.onBeforeCompile = (shader) => {
    Object.assign(shader.uniforms, uniforms);
    shader.vertexShader = shader.vertexShader
      .replace("#include <common>", "#include <common>\nvarying vec3 vBellWorld;")
      .replace(
        "#include <worldpos_vertex>",
        "#include <worldpos_vertex>\nvBellWorld = (modelMatrix * vec4(transformed, 1.0)).xyz;",
      );
    shader.fragmentShader = shader.fragmentShader
      .replace(
        "#include <common>",
        `#include <common>
varying vec3 vBellWorld;
uniform float rimFace, rimEdge, rimLighten, stripes, stripeTransmit;
uniform vec3 stripeColor, bellCentre;
float stripeWeight() {
  if (stripes <= 0.0) return 0.0;
  vec2 offset = vBellWorld.xy - bellCentre.xy;
  float phase = fract(atan(offset.x, offset.y) * stripes / (2.0 * PI));
  return clamp(max((0.3 - phase) / 0.2, (phase - 0.7) / 0.2), 0.0, 1.0);
}`,
      )
      .replace(
        "#include <color_fragment>",
        "#include <color_fragment>\nfloat stripe = stripeWeight();\ndiffuseColor.rgb = mix(diffuseColor.rgb, stripeColor, stripe);",
      )
      .replace(
        "#include <opaque_fragment>",
        `#include <opaque_fragment>
float rimWeight = pow(1.0 - clamp(abs(dot(normal, normalize(vViewPosition))), 0.0, 1.0), 1.5);
float transmit = (rimFace - (rimFace - rimEdge) * rimWeight) * (1.0 - (1.0 - stripeTransmit) * stripe);
gl_FragColor.rgb = mix(gl_FragColor.rgb, vec3(1.0), rimLighten * rimWeight);
gl_FragColor.a = 1.0 - transmit;`,
      );
  };
  material.userData.uniforms = uniforms;
  return material;
}

function makeBell(meta, faces) {
  const geometry = new THREE.BufferGeometry();
  const positions = new THREE.BufferAttribute(new Float32Array(meta.bell.vertices * 3), 3);
  positions.setUsage(THREE.DynamicDrawUsage);
  geometry.setAttribute("position", positions);
  geometry.setIndex(new THREE.BufferAttribute(faces, 1));
  const mesh = new THREE.Mesh(geometry, bellMaterial(meta.look));
  mesh.frustumCulled = false;
  return mesh;
}

// Line segments along every drawn tentacle, rebuilt when the drawn count changes.
function tentacleGeometry(count, particles) {
  const geometry = new THREE.BufferGeometry();
  const positions = new THREE.BufferAttribute(new Float32Array(count * particles * 3), 3);
  positions.setUsage(THREE.DynamicDrawUsage);
  geometry.setAttribute("position", positions);
  const index = new Uint32Array(count * (particles - 1) * 2);
  let k = 0;
  for (let t = 0; t < count; t++) {
    for (let p = 0; p < particles - 1; p++) {
      index[k++] = t * particles + p;
      index[k++] = t * particles + p + 1;
    }
  }
  geometry.setIndex(new THREE.BufferAttribute(index, 1));
  return geometry;
}

// A flat ribbon along each of `count` arms of `particles` points: two vertices a particle (the
// arm's two edges), two triangles a segment; positions set each frame by setRibbons.
function ribbonGeometry(count, particles) {
  const geometry = new THREE.BufferGeometry();
  const positions = new THREE.BufferAttribute(new Float32Array(count * particles * 6), 3);
  positions.setUsage(THREE.DynamicDrawUsage);
  geometry.setAttribute("position", positions);
  const index = new Uint32Array(count * (particles - 1) * 6);
  let k = 0;
  for (let t = 0; t < count; t++) {
    for (let p = 0; p < particles - 1; p++) {
      const a = 2 * (t * particles + p);
      index.set([a, a + 1, a + 2, a + 1, a + 3, a + 2], k);
      k += 6;
    }
  }
  geometry.setIndex(new THREE.BufferAttribute(index, 1));
  return geometry;
}

// The ribbons of arms `chains` (count x particles points, xyz) hanging about `centre`: the width
// of each starts radially out from the bell's axis (horizontal), kept across the local tangent,
// `width` m at the root narrowing to `taper` of it at the tip (the exports' ruffles left out).
function setRibbons(geometry, chains, count, particles, group, centre) {
  const positions = geometry.getAttribute("position");
  const point = (t, p) => new THREE.Vector3().fromArray(chains, 3 * (t * particles + p));
  for (let t = 0; t < count; t++) {
    const outward = point(t, 0).sub(centre).setZ(0);
    if (outward.lengthSq() === 0) outward.set(1, 0, 0);
    outward.normalize();
    for (let p = 0; p < particles; p++) {
      const tangent = point(t, Math.min(p + 1, particles - 1)).sub(point(t, Math.max(p - 1, 0))).normalize();
      const across = outward.clone().addScaledVector(tangent, -outward.dot(tangent));
      if (across.lengthSq() < 1e-12) across.copy(outward);
      across.normalize();
      const half = 0.5 * group.width * (1 - ((1 - group.taper) * p) / Math.max(particles - 1, 1));
      const middle = point(t, p);
      const v = 2 * (t * particles + p);
      positions.setXYZ(v, ...middle.clone().addScaledVector(across, -half).toArray());
      positions.setXYZ(v + 1, ...middle.clone().addScaledVector(across, half).toArray());
    }
  }
  positions.needsUpdate = true;
  geometry.computeVertexNormals();
}

// Points as large as the particles (diameter 2 radius): three.js scales an attenuated point's
// size by half the viewport height over the depth, which is 1 / (2 tan(fov / 2)) of the
// perspective projection's scale.
function makeFluid(meta, kinds, fov) {
  const count = meta.fluid.particles;
  const geometry = new THREE.BufferGeometry();
  const positions = new THREE.BufferAttribute(new Float32Array(count * 3), 3);
  const colors = new THREE.BufferAttribute(new Float32Array(count * 3), 3);
  positions.setUsage(THREE.DynamicDrawUsage);
  colors.setUsage(THREE.DynamicDrawUsage);
  geometry.setAttribute("position", positions);
  geometry.setAttribute("color", colors);
  const palette = KIND_COLORS.map((rgb) => linear(rgb));
  const disc = document.createElement("canvas"); // round points: a white disc as alpha mask
  disc.width = disc.height = 64;
  const pen = disc.getContext("2d");
  pen.fillStyle = "#fff";
  pen.beginPath();
  pen.arc(32, 32, 31, 0, 2 * Math.PI);
  pen.fill();
  const material = new THREE.PointsMaterial({
    size: (2 * meta.fluid.radius) / Math.tan(THREE.MathUtils.degToRad(fov) / 2),
    sizeAttenuation: true,
    vertexColors: true,
    map: new THREE.CanvasTexture(disc),
    alphaTest: 0.5,
  });
  const points = new THREE.Points(geometry, material);
  points.frustumCulled = false;
  points.userData.kindColors = (i) => palette[Math.min(kinds[i], palette.length - 1)];
  return points;
}

async function main() {
  const meta = await fetchMeta();
  const store = new FrameStore(meta);
  store.onError = showError;
  const [faces, kinds] = await Promise.all([
    meta.bell.present ? fetchBellFaces() : null,
    meta.fluid.present ? fetchFluidKinds() : null,
  ]);
  document.title = `${meta.name} · jellysim view`;

  const renderer = new THREE.WebGLRenderer({ antialias: true });
  renderer.setPixelRatio(window.devicePixelRatio);
  renderer.setSize(window.innerWidth, window.innerHeight);
  $("view").appendChild(renderer.domElement);

  const scene = new THREE.Scene();
  scene.background = linear(meta.look.water_color);
  const camera = new THREE.PerspectiveCamera(40, window.innerWidth / window.innerHeight, 1e-3, 1e3);
  camera.up.set(0, 0, 1); // z up (DESIGN §3); OrbitControls orbits about camera.up
  const controls = new OrbitControls(camera, renderer.domElement);
  controls.enableDamping = true;
  const sky = new THREE.HemisphereLight(0xdfefff, 0x203040, 1.6);
  sky.position.set(0, 0, 1);
  scene.add(sky);
  const headlight = new THREE.DirectionalLight(0xffffff, 1.6); // moves with the camera
  headlight.position.set(0.4, 0.6, 0);
  camera.add(headlight, headlight.target);
  headlight.target.position.set(0, 0, -1);
  scene.add(camera);

  const bell = meta.bell.present ? makeBell(meta, faces) : null;
  if (bell) {
    bell.name = "bell";
    scene.add(bell);
    drawnObjects.push(bell);
  }
  const tentacles = new THREE.LineSegments(
    new THREE.BufferGeometry(),
    // Lines face the camera: the tentacles' face-on colour (tentacle_transparency), as the
    // preview's ribbons and the middle of POV-Ray's tubes show them.
    new THREE.LineBasicMaterial({ color: linear(meta.look.tentacle_face_color) }),
  );
  tentacles.frustumCulled = false;
  // A scene of several tentacle groups: an object per group in its own colour, threads as
  // lines (face-on colour), oral arms as double-sided ribbons (lit, their colour).
  const groups = (meta.tentacles.groups ?? []).map((group) => {
    const object =
      group.form === "ribbon"
        ? new THREE.Mesh(
            ribbonGeometry(group.simulated, group.particles),
            new THREE.MeshPhongMaterial({
              color: linear(group.color),
              emissive: linear(group.emissive),
              transparent: group.opacity < 1,
              opacity: group.opacity,
              depthWrite: group.opacity >= 1,
              side: THREE.DoubleSide,
              shininess: group.shininess,
            }),
          )
        : new THREE.LineSegments(
            new THREE.BufferGeometry(),
            new THREE.LineBasicMaterial({ color: linear(group.face_color) }),
          );
    object.name = group.name;
    object.frustumCulled = false;
    object.userData.drawn = group.form === "ribbon" ? group.simulated : 0;
    scene.add(object);
    drawnObjects.push(object);
    return { group, object };
  });
  tentacles.name = "tentacles";
  if (groups.length === 0) {
    scene.add(tentacles);
    drawnObjects.push(tentacles);
  }
  const fluid = meta.fluid.present ? makeFluid(meta, kinds, camera.fov) : null;
  if (fluid) {
    fluid.name = "fluid";
    scene.add(fluid);
    drawnObjects.push(fluid);
  }

  // Controls: shown only for what the result has.
  $("bell-toggle").hidden = !bell;
  $("fluid-toggle").hidden = !fluid;
  $("interpolation-control").hidden = !meta.tentacles.present;
  const scrub = $("scrub");
  scrub.max = String(meta.frames - 1);
  const slider = $("interpolation");
  slider.max = String(meta.tentacles.max_interpolation);
  slider.value = String(meta.tentacles.interpolation);
  $("interpolation-value").textContent = slider.value;
  state.interpolation = meta.tentacles.interpolation;
  $("follow").checked = meta.travels;

  // Camera framing: the whole animation's box, or (following) one frame's size about the centre.
  let centre = null; // the jellyfish's centre in the frame drawn
  let drawn = null; // the data of the frame drawn
  function frameBox(low, high) {
    const middle = low.clone().add(high).multiplyScalar(0.5);
    const radius = Math.max(0.5 * high.clone().sub(low).length(), 1e-6);
    const vertical = THREE.MathUtils.degToRad(camera.fov);
    const horizontal = 2 * Math.atan(Math.tan(vertical / 2) * camera.aspect);
    const distance = (1.05 * radius) / Math.sin(Math.min(vertical, horizontal) / 2);
    camera.position.copy(middle).addScaledVector(VIEW_DIRECTION, -distance);
    camera.near = distance / 100;
    camera.far = 10 * (distance + radius);
    camera.updateProjectionMatrix();
    controls.target.copy(middle);
    controls.update();
  }
  function reframe() {
    if ($("follow").checked && drawn) {
      // A cube as large as the largest frame's box, about the middle of this frame's box.
      const box = new THREE.Box3();
      for (const array of Object.values(drawn)) {
        for (let i = 0; i < array.length; i += 3) {
          if (!Number.isNaN(array[i])) box.expandByPoint(new THREE.Vector3(array[i], array[i + 1], array[i + 2]));
        }
      }
      const middle = box.getCenter(new THREE.Vector3());
      const half = new THREE.Vector3().setScalar(0.5 * meta.extent);
      frameBox(middle.clone().sub(half), middle.clone().add(half));
    } else {
      frameBox(new THREE.Vector3(...meta.bounds[0]), new THREE.Vector3(...meta.bounds[1]));
    }
  }

  // The data of one frame, or null while some of it loads (then it is requested).
  function dataFor(frame) {
    const data = {};
    for (const part of ["bell", "tentacles", "fluid"]) {
      if (!meta[part].present || (part === "fluid" && !fluid.visible)) continue;
      data[part] = store.get(part, frame, state.interpolation);
      if (data[part] === null) return null;
    }
    return data;
  }

  function meanOf(array, stride, count) {
    const sum = new THREE.Vector3();
    for (let i = 0; i < count; i++) {
      sum.x += array[i * stride];
      sum.y += array[i * stride + 1];
      sum.z += array[i * stride + 2];
    }
    return sum.divideScalar(Math.max(count, 1));
  }

  function draw(frame, data) {
    if (data.bell) {
      const positions = bell.geometry.getAttribute("position");
      positions.array.set(data.bell);
      positions.needsUpdate = true;
      bell.geometry.computeVertexNormals();
      bell.material.userData.uniforms.bellCentre.value.copy(meanOf(data.bell, 3, meta.bell.vertices));
    }
    if (data.tentacles && groups.length > 0) {
      let offset = 0;
      let total = 0;
      const middle = data.bell ? meanOf(data.bell, 3, meta.bell.vertices) : null;
      for (const { group, object } of groups) {
        const count = drawnCount(group, state.interpolation);
        const floats = count * group.particles * 3;
        const chains = data.tentacles.subarray(offset, offset + floats);
        offset += floats;
        total += count;
        if (group.form === "ribbon") {
          const about = data.bell ? middle : meanOf(chains, 3 * group.particles, count);
          setRibbons(object.geometry, chains, count, group.particles, group, about);
          continue;
        }
        if (count !== object.userData.drawn) {
          object.geometry.dispose();
          object.geometry = tentacleGeometry(count, group.particles);
          object.userData.drawn = count;
        }
        const positions = object.geometry.getAttribute("position");
        positions.array.set(chains);
        positions.needsUpdate = true;
      }
      state.drawnTentacles = total;
    } else if (data.tentacles) {
      const particles = meta.tentacles.particles;
      const count = data.tentacles.length / (3 * particles);
      if (count !== state.drawnTentacles) {
        tentacles.geometry.dispose();
        tentacles.geometry = tentacleGeometry(count, particles);
        state.drawnTentacles = count;
      }
      const positions = tentacles.geometry.getAttribute("position");
      positions.array.set(data.tentacles);
      positions.needsUpdate = true;
    }
    if (data.fluid) {
      const positions = fluid.geometry.getAttribute("position");
      const colors = fluid.geometry.getAttribute("color");
      let alive = 0;
      for (let i = 0; i < meta.fluid.particles; i++) {
        const x = data.fluid[3 * i];
        if (Number.isNaN(x)) continue; // left the domain
        positions.setXYZ(alive, x, data.fluid[3 * i + 1], data.fluid[3 * i + 2]);
        const color = fluid.userData.kindColors(i);
        colors.setXYZ(alive, color.r, color.g, color.b);
        alive++;
      }
      fluid.geometry.setDrawRange(0, alive);
      positions.needsUpdate = true;
      colors.needsUpdate = true;
      state.fluidPoints = alive;
    }
    state.fluidPoints = fluid && fluid.visible ? state.fluidPoints : 0;

    // Following: move the camera with the jellyfish (the bell's centre, else the roots').
    const next = data.bell
      ? meanOf(data.bell, 3, meta.bell.vertices)
      : data.tentacles && groups.length === 0
        ? meanOf(data.tentacles, 3 * meta.tentacles.particles, state.drawnTentacles)
        : data.tentacles
          ? meanOf(data.tentacles, 3, data.tentacles.length / 3)
          : null;
    if (next && centre && $("follow").checked) {
      const shift = next.clone().sub(centre);
      camera.position.add(shift);
      controls.target.add(shift);
    }
    centre = next;
    drawn = data;

    state.frame = frame;
    if (!scrubbing) scrub.value = String(frame);
    const end = meta.time[meta.time.length - 1];
    $("clock").textContent =
      `t = ${meta.time[frame].toFixed(3)} s / ${end.toFixed(3)} s · frame ${frame} / ${meta.frames - 1}`;
    if (!state.ready) {
      state.ready = true;
      reframe();
    }
  }

  // Playback, scrubbing and the controls.
  let scrubbing = false;
  let dirty = true; // redraw even if the frame is the same (new tentacle count, fluid shown)
  const setPlaying = (playing) => {
    state.playing = playing;
    $("play").textContent = playing ? "Pause" : "Play";
  };
  $("play").addEventListener("click", (event) => {
    setPlaying(!state.playing);
    event.currentTarget.blur(); // the space bar stays with the page
  });
  document.addEventListener("keydown", (event) => {
    // Space plays and pauses, except where it works a control: a checkbox, the speed menu.
    if (event.code !== "Space" || event.target.matches("select, input[type=checkbox]")) return;
    event.preventDefault();
    setPlaying(!state.playing);
  });
  scrub.addEventListener("pointerdown", () => { scrubbing = true; });
  window.addEventListener("pointerup", () => { scrubbing = false; }); // released anywhere
  window.addEventListener("pointercancel", () => { scrubbing = false; });
  scrub.addEventListener("input", () => { state.position = Number(scrub.value); });
  $("speed").addEventListener("change", (event) => { state.speed = Number(event.target.value); });
  $("bell").addEventListener("change", (event) => { if (bell) bell.visible = event.target.checked; });
  $("fluid").addEventListener("change", (event) => {
    fluid.visible = event.target.checked;
    dirty = true;
  });
  slider.addEventListener("input", () => { $("interpolation-value").textContent = slider.value; });
  slider.addEventListener("change", () => {
    state.interpolation = Number(slider.value);
    dirty = true;
  });
  $("follow").addEventListener("change", reframe);
  $("reframe").addEventListener("click", (event) => {
    reframe();
    event.currentTarget.blur();
  });
  $("panel").addEventListener("submit", (event) => event.preventDefault());
  window.addEventListener("resize", () => {
    camera.aspect = window.innerWidth / window.innerHeight;
    camera.updateProjectionMatrix();
    renderer.setSize(window.innerWidth, window.innerHeight);
  });

  let last = performance.now();
  renderer.setAnimationLoop((now) => {
    const seconds = Math.min((now - last) / 1000, 0.25);
    last = now;
    if (state.playing && !scrubbing && state.ready) {
      const next = (state.position + seconds * meta.fps * state.speed) % meta.frames;
      if (dataFor(Math.floor(next)) !== null) state.position = next; // else wait for the data
    }
    const frame = Math.floor(state.position);
    if (frame !== state.frame || dirty) {
      const data = dataFor(frame);
      if (data !== null) {
        draw(frame, data);
        dirty = false;
      }
    }
    const waiting = frame !== state.frame || dirty;
    if (!state.error) {
      const flow = meta.flow ? ` · ${meta.flow}` : "";
      $("status").textContent = waiting ? "loading…" : `${meta.name}${flow}${meta.complete ? "" : " (incomplete run)"}`;
    }
    // Read ahead: the next chunk (wrapping to the start) of every part shown.
    for (const part of ["bell", "tentacles", "fluid"]) {
      if (meta[part].present && (part !== "fluid" || fluid.visible)) {
        store.loadAfter(part, frame, state.interpolation);
      }
    }
    controls.update();
    renderer.render(scene, camera);
  });
}

main().catch(showError);
