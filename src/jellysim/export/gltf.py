"""glTF 2.0 export: the animation as binary glTF (``.glb``) for three.js, Blender and the web.

Written with numpy, json and struct only (the glTF 2.0 specification, §4.4 for GLB).

Coordinates: jellysim's world is z up, metres; glTF's is y up, metres, right-handed. Every point
and normal is rotated by (x, y, z) -> (x, z, -y), a proper rotation (determinant +1), so
triangles keep their counter-clockwise winding seen from outside. A 2-D fluid's (x, y up) is
first placed at (x, 0, y) as the renderers do, which lands at (x, y, 0).

Representation: one node per exported frame, holding that frame's mesh, switched on and off by a
``scale`` animation with STEP interpolation (1 while its frame shows, 0 otherwise). Chosen over
morph targets because it plays in every viewer that plays glTF node animation (three.js's
GLTFLoader and AnimationMixer, Blender's importer, which turns STEP into constant keyframes)
with no limit on the frame count, whereas morph targets put one weight per frame in every
keyframe (data growing as frames squared) and three.js and Blender slow down with thousands of
targets. The animation data stays linear in the frame count: each frame node has at most three
keyframes. Without playing the animation a viewer shows the part's first frame only.

Each frame's mesh has a primitive per part, as the result has them:

- the bell's surface triangles (``bell/surface_vertices``, ``bell/surface_faces``) with smooth
  vertex normals; translucent material (alphaMode BLEND);
- per tentacle group (:mod:`jellysim.export.groups`), in the group's own material named after
  it (``tentacles`` in a one-group scene, ``tentacles_NAME`` otherwise): a thread group's drawn
  (interpolated) tentacles as closed tapered tubes, ``TUBE_SIDES`` vertices per particle around
  the polyline, radii from the group's look (as the renderers draw them), and a cap at the root
  and at the tip (tubes rather than LINES primitives because lines are one pixel wide in WebGL
  and Blender imports them as bare edges that do not render); a ribbon group's arms as their
  ruffled ribbon triangles with vertex normals (double-sided material);
- a fluid's live particles as POINTS (what viewers draw of them varies: a pixel in three.js,
  loose vertices in Blender).

Materials (pbrMetallicRoughness, linear RGB) are the shared ones of
:mod:`jellysim.render.materials`, as every renderer and export uses them: the bell double-sided
with base alpha ``1 - bell_transparency`` (alphaMode BLEND) and emission ``GLOW_EMISSION glow``
times its colour; each tentacle group opaque in its colour; the fluid ``FLUID_COLOR``. The bell's
rim and stripes are view-dependent shading glTF's core materials cannot express
(docs/rendering.md).

Long animations are split into parts so that no file nears GLB's 4 GiB (uint32) length limit or
a viewer's memory: ``<name>_part000.glb``, ``<name>_part001.glb``, ... each hold a contiguous run
of the requested frames and at most ``PART_BUDGET_BYTES`` (a part holds at least one frame
whatever its size), and ``<name>.gltf-parts.json`` lists the parts with their frames and times.
Every requested frame lands in exactly one part. Animation times are absolute, ``frame / fps``
seconds, so parts played one after the other continue each other; each part's last frame is held
for one frame interval (an extra keyframe at its end), so a part lasts as long as its frames do.
"""

from __future__ import annotations

import json
import os
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from jellysim import fields
from jellysim.errors import JellysimError
from jellysim.export.groups import ExportGroup, export_groups
from jellysim.io.result import Result
from jellysim.render.materials import Material, bell_material, fluid_material

PART_BUDGET_BYTES = 256 * 2**20  # most bytes of one .glb part (more only for a single frame)
TUBE_SIDES = 6  # vertices around a tentacle's tube at each particle
JSON_BYTES_PER_FRAME = 4096  # an upper bound of the JSON one frame adds to a part (tested)
JSON_BYTES_PER_GROUP = 1024  # and of what each tentacle group beyond the first adds to that
JSON_BYTES_FIXED = 8192  # an upper bound of the JSON a part holds besides its frames
GLB_LIMIT = 2**32 - 1  # GLB stores lengths as uint32

_GLB_MAGIC, _GLB_VERSION = 0x46546C67, 2  # "glTF"
_CHUNK_JSON, _CHUNK_BIN = 0x4E4F534A, 0x004E4942  # "JSON", "BIN\0"
_FLOAT, _UNSIGNED_SHORT, _UNSIGNED_INT = 5126, 5123, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_POINTS, _TRIANGLES = 0, 4


def to_y_up(points: np.ndarray) -> np.ndarray:
    """Z-up world vectors (..., 3) as glTF's y-up: (x, y, z) -> (x, z, -y)."""
    return np.stack([points[..., 0], points[..., 2], -points[..., 1]], axis=-1)


def _fluid_world(points: np.ndarray) -> np.ndarray:
    """Fluid positions (K, D), D = 2 or 3, as z-up world points (K, 3): 2-D (x, y) -> (x, 0, y)."""
    if points.shape[-1] == 3:
        return points
    world = np.zeros((*points.shape[:-1], 3))
    world[..., 0], world[..., 2] = points[..., 0], points[..., 1]
    return world


def tube_frames(chains: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit tangent, normal and binormal (N, P, 3) along polylines ``chains`` (N, P, 3).

    Tangents are central differences (one-sided at the ends); the normal is carried from the root
    by projecting the previous one onto each tangent's normal plane (a discrete parallel
    transport), so tubes do not twist; binormal = tangent x normal.
    """
    tangent = np.gradient(chains, axis=1)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=-1, keepdims=True), 1e-300)

    def perpendicular(reference: np.ndarray, t: np.ndarray) -> np.ndarray:
        v = reference - np.sum(reference * t, axis=-1, keepdims=True) * t
        return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)

    def fresh(t: np.ndarray) -> np.ndarray:
        helper = np.where(np.abs(t[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        return perpendicular(helper, t)

    normal = np.empty_like(chains)
    normal[:, 0] = fresh(tangent[:, 0])
    for i in range(1, chains.shape[1]):
        t = tangent[:, i]
        carried = normal[:, i - 1] - np.sum(normal[:, i - 1] * t, axis=-1, keepdims=True) * t
        length = np.linalg.norm(carried, axis=-1, keepdims=True)
        normal[:, i] = np.where(length > 1e-6, carried / np.maximum(length, 1e-300), fresh(t))
    return tangent, normal, np.cross(tangent, normal)


def tube_vertices(
    chains: np.ndarray, radii: np.ndarray, sides: int = TUBE_SIDES
) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and unit normals (N * (P * sides + 2), 3) of tubes around ``chains`` (N, P, 3) m
    of radius ``radii`` (P,) m: per chain, ``sides`` vertices around each particle (ring i,
    vertex s at angle 2 pi s / sides from the normal towards the binormal), then the root's and
    the tip's centre (the caps, with normals -tangent and +tangent)."""
    count, particles, _ = chains.shape
    tangent, normal, binormal = tube_frames(chains)
    angles = 2.0 * np.pi * np.arange(sides) / sides
    around = (
        np.cos(angles)[None, None, :, None] * normal[:, :, None, :]
        + np.sin(angles)[None, None, :, None] * binormal[:, :, None, :]
    )  # (N, P, S, 3) unit
    ring = chains[:, :, None, :] + radii[None, :, None, None] * around
    positions = np.concatenate(
        [ring.reshape(count, particles * sides, 3), chains[:, :1], chains[:, -1:]], axis=1
    )
    normals = np.concatenate(
        [around.reshape(count, particles * sides, 3), -tangent[:, :1], tangent[:, -1:]], axis=1
    )
    return positions.reshape(-1, 3), normals.reshape(-1, 3)


def tube_faces(count: int, particles: int, sides: int = TUBE_SIDES) -> np.ndarray:
    """Triangles (M, 3) over :func:`tube_vertices`, counter-clockwise seen from outside."""
    per_chain = particles * sides + 2
    ring = np.repeat(np.arange(particles - 1), sides)
    around = np.tile(np.arange(sides), particles - 1)
    a, b = ring * sides + around, ring * sides + (around + 1) % sides  # ring i
    c, d = a + sides, b + sides  # ring i + 1
    side = np.concatenate([np.stack([a, b, c], axis=1), np.stack([b, d, c], axis=1)])
    s = np.arange(sides)
    nxt = (s + 1) % sides
    root_centre, tip_centre = particles * sides, particles * sides + 1
    last = (particles - 1) * sides
    root = np.stack([np.full(sides, root_centre), nxt, s], axis=1)
    tip = np.stack([np.full(sides, tip_centre), last + s, last + nxt], axis=1)
    one = np.concatenate([side, root, tip])
    offsets = per_chain * np.arange(count)[:, None, None]
    return (one[None] + offsets).reshape(-1, 3)


def _bell_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    from jellysim.render.frame import vertex_normals

    normals = vertex_normals(vertices, faces)
    unused = np.linalg.norm(normals, axis=1) == 0.0  # vertices in no triangle: any unit vector
    normals[unused] = (0.0, 0.0, 1.0)
    return normals


def _indices(faces: np.ndarray) -> np.ndarray:
    """Triangle indices flattened as uint16 where they fit (65535 is reserved), else uint32."""
    kind = np.uint16 if faces.size and int(faces.max()) < 65535 else np.uint32
    return np.ascontiguousarray(faces.ravel(), dtype=kind)


def _padded(data: bytes, fill: bytes = b"\0") -> bytes:
    return data + fill * (-len(data) % 4)


@dataclass
class _Part:
    """The JSON and the binary chunk of one .glb, built up piece by piece."""

    buffer_views: list[dict[str, Any]] = field(default_factory=list)
    accessors: list[dict[str, Any]] = field(default_factory=list)
    chunks: list[bytes] = field(default_factory=list)
    length: int = 0

    def view(self, data: bytes, target: int | None = None, stride: int | None = None) -> int:
        """Append ``data`` (4-byte aligned) as a new buffer view; returns its index."""
        entry: dict[str, Any] = {"buffer": 0, "byteOffset": self.length, "byteLength": len(data)}
        if stride is not None:
            entry["byteStride"] = stride
        if target is not None:
            entry["target"] = target
        padded = _padded(data)
        self.chunks.append(padded)
        self.length += len(padded)
        self.buffer_views.append(entry)
        return len(self.buffer_views) - 1

    def accessor(
        self, view: int, offset: int, array: np.ndarray, kind: str, bounds: bool = False
    ) -> int:
        """An accessor over ``array`` (float32 VEC3/SCALAR or uint16/uint32 SCALAR) stored at
        ``offset`` bytes into buffer view ``view``; ``bounds`` adds its min and max."""
        component = {
            np.dtype(np.float32): _FLOAT,
            np.dtype(np.uint16): _UNSIGNED_SHORT,
            np.dtype(np.uint32): _UNSIGNED_INT,
        }[array.dtype]
        rows = array.reshape(len(array), -1)
        entry: dict[str, Any] = {
            "bufferView": view,
            "byteOffset": offset,
            "componentType": component,
            "count": len(array),
            "type": kind,
        }
        if bounds:
            entry["min"] = [float(v) for v in rows.min(axis=0)]
            entry["max"] = [float(v) for v in rows.max(axis=0)]
        self.accessors.append(entry)
        return len(self.accessors) - 1


@dataclass(frozen=True)
class _Source:
    """What one result contributes per frame, read once."""

    fps: float
    name: str
    bell_vertices: Any  # h5py dataset (F, V, 3) m, or None
    bell_faces: np.ndarray | None  # (M, 3) int
    groups: list[ExportGroup]  # the tentacle groups, drawn
    fluid_position: Any  # h5py dataset (F, K, D) m, or None
    fluid_alive: np.ndarray | None  # (F, K) bool
    look: Any  # jellysim.render.frame.Look

    def frame_bytes(self, frame: int) -> int:
        """Bytes of binary data frame ``frame`` adds to a part (vertex data and keyframes)."""
        vec3 = 12
        total = 3 * 4 + 3 * vec3  # at most three keyframes: times and scales
        if self.bell_vertices is not None:
            total += 2 * vec3 * self.bell_vertices.shape[1]
        for group in self.groups:
            if group.ribbon:
                arms = group.ribbon_meshes(frame)
                total += 2 * vec3 * len(arms.vertices)
                total += len(_padded(_indices(arms.faces).tobytes()))
            else:
                count, particles = group.positions.shape[1:3]
                total += 2 * vec3 * count * (particles * TUBE_SIDES + 2)
        if self.fluid_alive is not None:
            total += vec3 * int(self.fluid_alive[frame].sum())
        return total

    def shared_bytes(self) -> int:
        """Bytes of binary data every part holds once (the triangle indices)."""
        total = 0
        if self.bell_faces is not None:
            total += len(_padded(_indices(self.bell_faces).tobytes()))
        for group in self.groups:
            if not group.ribbon:
                count, particles = group.positions.shape[1:3]
                total += len(_padded(_indices(tube_faces(count, particles)).tobytes()))
        return total

    def json_bytes_per_frame(self) -> int:
        """An upper bound of the JSON one frame adds to a part."""
        return JSON_BYTES_PER_FRAME + JSON_BYTES_PER_GROUP * max(len(self.groups) - 1, 0)


def _read(result: Result, interpolation: int | None) -> _Source:
    from jellysim.render.pipeline import scene_look

    scene = result.scene
    look = scene_look(scene)
    has_bell = result.has(fields.BELL_SURFACE_VERTICES) and result.has(fields.BELL_SURFACE_FACES)
    fluid = result.dataset(fields.FLUID_POSITION) if result.has(fields.FLUID_POSITION) else None
    alive = None
    if fluid is not None:
        alive = (
            result.fluid_alive
            if result.has(fields.FLUID_ALIVE)
            else np.ones((result.frames, fluid.shape[1]), dtype=bool)
        )
    return _Source(
        fps=float(result.file.attrs["fps"]),
        name=scene.name,
        bell_vertices=result.dataset(fields.BELL_SURFACE_VERTICES) if has_bell else None,
        bell_faces=result.bell_surface_faces.astype(np.int64) if has_bell else None,
        groups=export_groups(result, look, interpolation),
        fluid_position=fluid,
        fluid_alive=alive,
        look=look,
    )


def _plan_parts(source: _Source, frames: range, budget: int) -> list[range]:
    """Split ``frames`` into contiguous runs whose .glb stays within ``budget`` bytes (a run
    holds at least one frame). Every frame lands in exactly one run, in order."""
    fixed = 28 + JSON_BYTES_FIXED + source.shared_bytes()  # GLB header and chunk headers: 28
    parts: list[range] = []
    start, size = 0, fixed
    for k, frame in enumerate(frames):
        extra = source.frame_bytes(frame) + source.json_bytes_per_frame()
        if k > start and size + extra > budget:
            parts.append(frames[start:k])
            start, size = k, fixed
        size += extra
    parts.append(frames[start:])
    return parts


def generator() -> str:
    """The ``asset.generator`` string."""
    from jellysim._version import __version__

    return f"jellysim {__version__} (jellysim export --format gltf)"


def _material(material: Material, **extra: Any) -> dict[str, Any]:
    """A glTF pbrMetallicRoughness material from a shared one (linear RGB, as glTF wants)."""
    return {
        "name": material.name,
        "pbrMetallicRoughness": {
            "baseColorFactor": [*map(float, material.base_color), float(material.opacity)],
            "metallicFactor": 0.0,
            "roughnessFactor": float(material.roughness),
        },
        **extra,
    }


def _keyframes(times: np.ndarray, index: int, hold: float) -> tuple[list[float], list[float]]:
    """STEP keyframes (times s, scales) showing frame ``index`` of ``times`` only: from the
    part's start it is hidden, then shown at its own time until the next frame's; the last frame
    stays shown until ``hold`` seconds after its time."""
    keys: list[tuple[float, float]] = []
    if index > 0:
        keys.append((float(times[0]), 0.0))
    keys.append((float(times[index]), 1.0))
    if index + 1 < len(times):
        keys.append((float(times[index + 1]), 0.0))
    else:
        keys.append((float(times[index] + np.float32(hold)), 1.0))
    return [t for t, _ in keys], [s for _, s in keys]


def _build_part(
    source: _Source, frames: range, every: int, part: int, parts: int
) -> tuple[dict[str, Any], list[bytes]]:
    """The glTF JSON and the binary chunk (in 4-byte aligned pieces) of one part holding
    ``frames``."""
    look = source.look
    built = _Part()
    materials: list[dict[str, Any]] = []
    shared: dict[str, tuple[int, int]] = {}  # primitive kind: (index accessor, material)
    if source.bell_faces is not None:
        indices = _indices(source.bell_faces)
        view = built.view(indices.tobytes(), _ELEMENT_ARRAY_BUFFER)
        bell = bell_material(look)
        materials.append(
            _material(
                bell,
                emissiveFactor=[float(c) for c in bell.emissive],
                alphaMode="BLEND",
                doubleSided=True,
            )
        )
        shared["bell"] = (built.accessor(view, 0, indices, "SCALAR"), len(materials) - 1)
    for group in source.groups:
        if group.ribbon:
            materials.append(_material(group.material, doubleSided=True))
            shared[group.part] = (-1, len(materials) - 1)  # indices per frame
            continue
        count, particles = group.positions.shape[1:3]
        indices = _indices(tube_faces(count, particles))
        view = built.view(indices.tobytes(), _ELEMENT_ARRAY_BUFFER)
        materials.append(_material(group.material))
        shared[group.part] = (built.accessor(view, 0, indices, "SCALAR"), len(materials) - 1)
    if source.fluid_position is not None:
        materials.append(_material(fluid_material()))
        shared["fluid"] = (-1, len(materials) - 1)

    times = (np.asarray(frames, dtype=np.float64) / source.fps).astype(np.float32)
    hold = every / source.fps
    meshes: list[dict[str, Any]] = []
    frame_nodes: list[dict[str, Any]] = []
    key_times: list[np.ndarray] = []
    key_scales: list[np.ndarray] = []
    for index, frame in enumerate(frames):
        # Vertex data of the frame, all VEC3 float32, in one strided view.
        arrays: list[tuple[str, np.ndarray]] = []
        if source.bell_vertices is not None and source.bell_faces is not None:
            vertices = np.asarray(source.bell_vertices[frame], dtype=np.float64)
            arrays.append(("bell", to_y_up(vertices)))
            arrays.append(("bell-normal", to_y_up(_bell_normals(vertices, source.bell_faces))))
        ribbon_faces: dict[str, np.ndarray] = {}
        for group in source.groups:
            if group.ribbon:
                positions, faces, normals, _ = group.ribbon_meshes(frame)
                if not len(faces):
                    continue
                ribbon_faces[group.part] = faces
            else:
                positions, normals = tube_vertices(group.positions[frame], group.radii)
            arrays.append((group.part, to_y_up(positions)))
            arrays.append((f"{group.part}-normal", to_y_up(normals)))
        if source.fluid_position is not None and source.fluid_alive is not None:
            alive = source.fluid_alive[frame]
            if alive.any():
                points = np.asarray(source.fluid_position[frame], dtype=np.float64)[alive]
                arrays.append(("fluid", to_y_up(_fluid_world(points))))
        node: dict[str, Any] = {"name": f"frame_{frame:05d}"}
        if arrays:
            stored = [(name, np.ascontiguousarray(a, dtype=np.float32)) for name, a in arrays]
            view = built.view(b"".join(a.tobytes() for _, a in stored), _ARRAY_BUFFER, 12)
            accessors: dict[str, int] = {}
            offset = 0
            for name, array in stored:
                accessors[name] = built.accessor(
                    view, offset, array, "VEC3", bounds=not name.endswith("normal")
                )
                offset += array.nbytes
            primitives = []
            for name in ("bell", *(group.part for group in source.groups), "fluid"):
                if name not in accessors:
                    continue
                indices_accessor, material = shared[name]
                if name in ribbon_faces:
                    indices = _indices(ribbon_faces[name])
                    indices_view = built.view(indices.tobytes(), _ELEMENT_ARRAY_BUFFER)
                    indices_accessor = built.accessor(indices_view, 0, indices, "SCALAR")
                attributes = {"POSITION": accessors[name]}
                primitive: dict[str, Any] = {"attributes": attributes, "material": material}
                if name == "fluid":
                    primitive["mode"] = _POINTS
                else:
                    attributes["NORMAL"] = accessors[f"{name}-normal"]
                    primitive["indices"] = indices_accessor
                    primitive["mode"] = _TRIANGLES
                primitives.append(primitive)
            meshes.append({"name": f"frame_{frame:05d}", "primitives": primitives})
            node["mesh"] = len(meshes) - 1
        if index > 0:
            node["scale"] = [0.0, 0.0, 0.0]
        frame_nodes.append(node)
        seconds, scales = _keyframes(times, index, hold)
        key_times.append(np.asarray(seconds, dtype=np.float32))
        key_scales.append(np.repeat(np.asarray(scales, dtype=np.float32), 3).reshape(-1, 3))

    # Keyframes: all inputs in one view, all outputs in another.
    inputs_view = built.view(b"".join(t.tobytes() for t in key_times))
    outputs_view = built.view(b"".join(s.tobytes() for s in key_scales))
    samplers, channels = [], []
    input_offset = output_offset = 0
    for node_index, (seconds_array, scales_array) in enumerate(
        zip(key_times, key_scales, strict=True)
    ):
        sampler = {
            "input": built.accessor(
                inputs_view, input_offset, seconds_array, "SCALAR", bounds=True
            ),
            "output": built.accessor(outputs_view, output_offset, scales_array, "VEC3"),
            "interpolation": "STEP",
        }
        input_offset += seconds_array.nbytes
        output_offset += scales_array.nbytes
        samplers.append(sampler)
        channels.append(
            {"sampler": len(samplers) - 1, "target": {"node": node_index + 1, "path": "scale"}}
        )

    root = {"name": source.name, "children": list(range(1, len(frame_nodes) + 1))}
    document: dict[str, Any] = {
        "asset": {
            "version": "2.0",
            "generator": generator(),
            "extras": {
                "fps": source.fps,
                "first_frame": frames[0],
                "last_frame": frames[-1],
                "frame_step": every,
                "part": part,
                "parts": parts,
                "up": "+y (jellysim's +z)",
                "units": "m",
            },
        },
        "scene": 0,
        "scenes": [{"name": source.name, "nodes": [0]}],
        "nodes": [root, *frame_nodes],
        "meshes": meshes,
        "materials": materials,
        "animations": [{"name": source.name, "channels": channels, "samplers": samplers}],
        "accessors": built.accessors,
        "bufferViews": built.buffer_views,
        "buffers": [{"byteLength": built.length}],
    }
    for key in ("meshes", "materials"):
        if not document[key]:
            del document[key]
    return document, built.chunks


def _glb_bytes(document: dict[str, Any], binary: list[bytes]) -> list[bytes]:
    """A GLB file's pieces in order (header, JSON chunk, binary chunk from ``binary``, pieces
    of 4-byte aligned lengths); raises JellysimError when the file would exceed GLB's uint32
    length."""
    text = _padded(json.dumps(document, separators=(",", ":")).encode("utf-8"), b" ")
    binary_length = sum(len(piece) for piece in binary)
    total = 12 + 8 + len(text) + 8 + binary_length
    if total > GLB_LIMIT:
        raise JellysimError(
            f"a part needs {total} bytes, more than a GLB file holds (4 GiB): "
            "export fewer tentacles (--interpolation) or use --format usd"
        )
    return [
        struct.pack("<III", _GLB_MAGIC, _GLB_VERSION, total),
        struct.pack("<II", len(text), _CHUNK_JSON),
        text,
        struct.pack("<II", binary_length, _CHUNK_BIN),
        *binary,
    ]


def _write(path: Path, pieces: list[bytes]) -> None:
    temporary = path.with_name(f".{path.name}.tmp")
    with open(temporary, "wb") as stream:
        for piece in pieces:
            stream.write(piece)
    os.replace(temporary, path)


def export_gltf(
    result: Result,
    out: Path,
    frames: range,
    interpolation: int | None = None,
    budget: int | None = None,
) -> list[Path]:
    """Write ``frames`` as ``OUT/<name>_partNNN.glb`` and the index ``OUT/<name>.gltf-parts.json``;
    returns the parts, then the index. ``budget``: bytes per part (``PART_BUDGET_BYTES``)."""
    source = _read(result, interpolation)
    every = frames.step
    runs = _plan_parts(source, frames, PART_BUDGET_BYTES if budget is None else budget)
    paths = []
    entries = []
    for part, run in enumerate(runs):
        path = out / f"{source.name}_part{part:03d}.glb"
        document, binary = _build_part(source, run, every, part, len(runs))
        _write(path, _glb_bytes(document, binary))
        paths.append(path)
        entries.append(
            {
                "file": path.name,
                "first_frame": run[0],
                "last_frame": run[-1],
                "frame_count": len(run),
                "start_time": run[0] / source.fps,
                "end_time": (run[-1] + every) / source.fps,
                "bytes": path.stat().st_size,
            }
        )
    index = {
        "generator": generator(),
        "name": source.name,
        "fps": source.fps,
        "frames": {
            "first": frames[0],
            "last": frames[-1],
            "step": every,
            "count": len(frames),
        },
        "up": "+y",
        "units": "m",
        "parts": entries,
    }
    index_path = out / f"{source.name}.gltf-parts.json"
    _write(index_path, [(json.dumps(index, indent=2) + "\n").encode("utf-8")])
    # Parts of an earlier, longer export would be mistaken for this one's.
    own = re.compile(re.escape(source.name) + r"_part\d{3,}\.glb")
    for stale in out.iterdir():
        if own.fullmatch(stale.name) and stale not in paths:
            stale.unlink()
    return [*paths, index_path]
