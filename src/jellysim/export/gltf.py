"""glTF 2.0 export: the animation as binary glTF (``.glb``) for three.js, Blender and the web.

Written with numpy, json and struct only (the glTF 2.0 specification, §4.4 for GLB).

Coordinates: jellysim's world is z up, metres; glTF's is y up, metres, right-handed. Every point
and normal is rotated by (x, y, z) -> (x, z, -y), a proper rotation (determinant +1), so
triangles keep their counter-clockwise winding seen from outside. A 2-D fluid's (x, y up) is
first placed at (x, 0, y) as the renderers do, which lands at (x, y, 0).

Representation: one node and one mesh per object (``bell``, each tentacle group's part,
``fluid``), children of a root node named after the scene. A part's first frame is the mesh's
own geometry; every later frame k is a morph target holding frame k's POSITION and NORMAL minus
the first's; a ``weights`` animation with STEP interpolation sets target k's weight to 1 (the
others 0) from frame k's time until the next frame's, so viewers draw one frame's geometry at a
time: one draw call per object (three.js), one object with a shape key per frame (Blender's
importer, STEP keys as constant keyframes). Morph targets need one vertex count and one
triangle list per object over the frames: a ribbon group is built with the most centreline
stations any exported frame needs (:meth:`~jellysim.export.groups.ExportGroup.ribbon_subdivisions`)
and keeps all its grid triangles; a fluid keeps every particle, a dead one drawn on a live one
of the same frame (a point drawn twice looks like one), and its node is scaled to 0 (STEP) at
frames with no live particle. The weights grow as frames squared (one weight per target per
keyframe), and three.js passes one uniform per target to its shaders, so a part holds at most
``MORPH_FRAMES_MAX`` frames (docs/decisions.md). Without playing the animation a viewer shows
the part's first frame.

Each object is a mesh of one primitive, as the result has them:

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
whatever its size) and at most ``MORPH_FRAMES_MAX`` frames, and ``<name>.gltf-parts.json``
lists the parts with their frames and times. Every requested frame lands in exactly one part.
Animation times are absolute, ``frame / fps`` seconds, so parts played one after the other
continue each other; each part's last frame is held for one frame interval (an extra keyframe at
its end), so a part's animation spans exactly its frames' time: ``first / fps`` to
``(last + every) / fps``. The glTF scene's ``extras`` carry ``fps``, ``frame_start``,
``frame_end`` and ``frame_step`` (frame indices, as Blender numbers its frames when its frame
rate is the fps), and under ``jellysim`` the settings the Blender import script reads
(:mod:`jellysim.export.blender_settings`: the look's colours, the part's frames and bounds, the
renderers' camera path), as the USD export writes them into its stage. Blender's importer keeps
these extras as custom properties of its scene but sets neither its frame range nor its frame
rate from a file; ``import_into_blender.py``, written beside the parts, does (docs/exports.md).
"""

from __future__ import annotations

import json
import os
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from jellysim import fields
from jellysim.errors import JellysimError
from jellysim.export.blender_settings import (
    BLENDER_SCRIPT,
    blender_settings,
    camera_path,
    write_blender_script,
)
from jellysim.export.groups import ExportGroup, export_groups
from jellysim.io.result import Result
from jellysim.render.materials import Material, bell_material, fluid_material

PART_BUDGET_BYTES = 512 * 2**20  # most bytes of one .glb part (more only for a single frame)
MORPH_FRAMES_MAX = (
    600  # most frames of one part: morph targets per mesh, plus its own (20 s at 30 fps)
)
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


class _Geometry(NamedTuple):
    """One object at one frame, y up: ``positions`` (V, 3) m, ``normals`` (V, 3) unit or None
    (points), ``shown`` False where it has nothing to draw (a fluid with no live particle)."""

    positions: np.ndarray
    normals: np.ndarray | None
    shown: bool


@dataclass(frozen=True)
class _Source:
    """What one result contributes per frame, read once."""

    fps: float
    name: str
    bell_vertices: Any  # h5py dataset (F, V, 3) m, or None
    bell_faces: np.ndarray | None  # (M, 3) int
    groups: list[ExportGroup]  # the tentacle groups, drawn
    subdivisions: dict[str, int]  # per ribbon group's part: stations per segment (all frames)
    fluid_position: Any  # h5py dataset (F, K, D) m, or None
    fluid_alive: np.ndarray | None  # (F, K) bool
    look: Any  # jellysim.render.frame.Look

    def objects(self) -> list[str]:
        """The objects' names, in file order: ``bell``, each group's part, ``fluid``."""
        names = ["bell"] if self.bell_faces is not None else []
        names += [group.part for group in self.groups]
        return names + (["fluid"] if self.fluid_position is not None else [])

    def geometry(self, frame: int) -> dict[str, _Geometry]:
        """Every object at ``frame`` (y up, float64)."""
        out: dict[str, _Geometry] = {}
        if self.bell_vertices is not None and self.bell_faces is not None:
            vertices = np.asarray(self.bell_vertices[frame], dtype=np.float64)
            normals = _bell_normals(vertices, self.bell_faces)
            out["bell"] = _Geometry(to_y_up(vertices), to_y_up(normals), True)
        for group in self.groups:
            if group.ribbon:
                arms = group.ribbon_meshes(frame, self.subdivisions[group.part])
                positions, normals = arms.vertices, arms.normals
            else:
                positions, normals = tube_vertices(group.positions[frame], group.radii)
            out[group.part] = _Geometry(to_y_up(positions), to_y_up(normals), True)
        if self.fluid_position is not None and self.fluid_alive is not None:
            points = _fluid_world(np.asarray(self.fluid_position[frame], dtype=np.float64))
            alive = self.fluid_alive[frame]
            if alive.any():  # a dead particle drawn on the first live one
                points = np.where(alive[:, None], points, points[np.argmax(alive)])
            out["fluid"] = _Geometry(to_y_up(points), None, bool(alive.any()))
        return out

    def ribbon_faces(self, group: ExportGroup, frame: int) -> np.ndarray:
        """A ribbon group's triangles (M, 3), the same at every exported frame: each arm's whole
        grid (:func:`~jellysim.render.ribbons.grid_faces`) at the group's subdivisions."""
        from jellysim.render.ribbons import ROWS, grid_faces

        arms = group.ribbon_meshes(frame, self.subdivisions[group.part])
        counts = np.bincount(arms.arm, minlength=group.positions.shape[1])
        offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
        faces = [
            grid_faces(count // ROWS, ROWS).astype(np.int64) + offset
            for count, offset in zip(counts, offsets, strict=True)
            if count
        ]
        return np.concatenate(faces) if faces else np.empty((0, 3), np.int64)

    def vertices(self) -> dict[str, int]:
        """Vertices per object (the same at every frame)."""
        first = self.geometry(0)
        return {name: len(g.positions) for name, g in first.items()}

    def frame_bytes(self) -> int:
        """Bytes of binary data each frame adds to a part: its morph targets (POSITION and,
        but for the fluid, NORMAL deltas), besides the weights (:func:`weights_bytes`)."""
        vec3 = 12
        return sum(
            (1 if name == "fluid" else 2) * vec3 * count for name, count in self.vertices().items()
        )

    def shared_bytes(self) -> int:
        """Bytes of binary data every part holds once (triangle indices)."""
        total = 0
        if self.bell_faces is not None:
            total += len(_padded(_indices(self.bell_faces).tobytes()))
        for group in self.groups:
            if group.ribbon:
                faces = self.ribbon_faces(group, 0)
            else:
                count, particles = group.positions.shape[1:3]
                faces = tube_faces(count, particles)
            total += len(_padded(_indices(faces).tobytes()))
        return total

    def json_bytes_per_frame(self) -> int:
        """An upper bound of the JSON one frame adds to a part."""
        return JSON_BYTES_PER_FRAME + JSON_BYTES_PER_GROUP * max(len(self.groups) - 1, 0)


def weights_bytes(frames: int) -> int:
    """Bytes of a part's keyframes over ``frames`` frames: times, and one weight per morph
    target (``frames - 1``) at each keyframe (``frames + 1``), shared by every object; the
    fluid's scales."""
    return 4 * (frames + 1) * (1 + max(frames - 1, 0)) + 12 * (frames + 1)


def _read(result: Result, interpolation: int | None, frames: range) -> _Source:
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
    groups = export_groups(result, look, interpolation)
    return _Source(
        fps=float(result.file.attrs["fps"]),
        name=scene.name,
        bell_vertices=result.dataset(fields.BELL_SURFACE_VERTICES) if has_bell else None,
        bell_faces=result.bell_surface_faces.astype(np.int64) if has_bell else None,
        groups=groups,
        subdivisions={g.part: g.ribbon_subdivisions(frames) for g in groups if g.ribbon},
        fluid_position=fluid,
        fluid_alive=alive,
        look=look,
    )


def _plan_parts(source: _Source, frames: range, budget: int) -> list[range]:
    """Split ``frames`` into contiguous runs of at most ``MORPH_FRAMES_MAX`` frames whose .glb
    stays within ``budget`` bytes (a run holds at least one frame). Every frame lands in exactly
    one run, in order."""
    fixed = 28 + JSON_BYTES_FIXED + source.shared_bytes()  # GLB header and chunk headers: 28
    extra = source.frame_bytes() + source.json_bytes_per_frame()
    parts: list[range] = []
    start = 0
    for k in range(1, len(frames)):
        count = k - start + 1  # frames[start : k + 1]
        size = fixed + count * extra + weights_bytes(count)
        if count > MORPH_FRAMES_MAX or size > budget:
            parts.append(frames[start:k])
            start = k
    parts.append(frames[start:])
    return parts


def generator() -> str:
    """The ``asset.generator`` string."""
    from jellysim._version import __version__

    return f"jellysim {__version__} (jellysim export --format gltf)"


def _material(material: Material, **extra: Any) -> dict[str, Any]:
    """A glTF pbrMetallicRoughness material from a shared one (linear RGB, as glTF wants):
    translucent (alphaMode BLEND) where its opacity is under 1, glowing (``emissiveFactor``)
    where it emits."""
    out: dict[str, Any] = {
        "name": material.name,
        "pbrMetallicRoughness": {
            "baseColorFactor": [*map(float, material.base_color), float(material.opacity)],
            "metallicFactor": 0.0,
            "roughnessFactor": float(material.roughness),
        },
    }
    if any(c > 0.0 for c in material.emissive):
        out["emissiveFactor"] = [float(c) for c in material.emissive]
    if material.opacity < 1.0:
        out["alphaMode"] = "BLEND"
    return {**out, **extra}


def _world_box(geometry: list[dict[str, _Geometry]]) -> tuple[np.ndarray, np.ndarray]:
    """The corners (3,) m, jellysim's z up, of the box around every object drawn in
    ``geometry`` (objects per frame, y up); zeros where nothing is drawn."""
    boxes = [
        (g.positions.min(axis=0), g.positions.max(axis=0))
        for objects in geometry
        for g in objects.values()
        if g.shown and len(g.positions)
    ]
    if not boxes:
        return np.zeros(3), np.zeros(3)
    low = np.min([box[0] for box in boxes], axis=0)
    high = np.max([box[1] for box in boxes], axis=0)
    # y up (X, Y, Z) is z up (X, -Z, Y): the lowest -Z is minus the highest Z.
    return np.array([low[0], -high[2], low[1]]), np.array([high[0], -low[2], high[1]])


def _build_part(
    source: _Source, frames: range, every: int, part: int, parts: int
) -> tuple[dict[str, Any], list[bytes], tuple[np.ndarray, np.ndarray]]:
    """The glTF JSON and the binary chunk (in 4-byte aligned pieces) of one part holding
    ``frames``: a node and a mesh per object, later frames as morph targets; and the box (z up,
    m) around everything drawn in them."""
    look = source.look
    built = _Part()
    materials: list[dict[str, Any]] = []
    faces: dict[str, np.ndarray] = {}
    material_of: dict[str, int] = {}
    if source.bell_faces is not None:
        bell = bell_material(look)
        materials.append(_material(bell, doubleSided=True))
        material_of["bell"], faces["bell"] = len(materials) - 1, source.bell_faces
    for group in source.groups:
        if group.ribbon:
            materials.append(_material(group.material, doubleSided=True))
            faces[group.part] = source.ribbon_faces(group, frames[0])
        else:
            materials.append(_material(group.material))
            count, particles = group.positions.shape[1:3]
            faces[group.part] = tube_faces(count, particles)
        material_of[group.part] = len(materials) - 1
    if source.fluid_position is not None:
        materials.append(_material(fluid_material()))
        material_of["fluid"] = len(materials) - 1

    names = source.objects()
    geometry = [source.geometry(frame) for frame in frames]
    targets = len(frames) - 1
    target_names = [f"frame_{frame:05d}" for frame in frames[1:]]
    meshes: list[dict[str, Any]] = []
    nodes: list[dict[str, Any]] = []
    for name in names:
        first = geometry[0][name]
        arrays = [np.ascontiguousarray(first.positions, dtype=np.float32)]
        if first.normals is not None:
            arrays.append(np.ascontiguousarray(first.normals, dtype=np.float32))
        view = built.view(b"".join(a.tobytes() for a in arrays), _ARRAY_BUFFER, 12)
        attributes = {"POSITION": built.accessor(view, 0, arrays[0], "VEC3", bounds=True)}
        if first.normals is not None:
            attributes["NORMAL"] = built.accessor(view, arrays[0].nbytes, arrays[1], "VEC3")
        primitive: dict[str, Any] = {"attributes": attributes, "material": material_of[name]}
        if name in faces:
            indices = _indices(faces[name])
            indices_view = built.view(indices.tobytes(), _ELEMENT_ARRAY_BUFFER)
            primitive["indices"] = built.accessor(indices_view, 0, indices, "SCALAR")
            primitive["mode"] = _TRIANGLES
        else:
            primitive["mode"] = _POINTS
        mesh: dict[str, Any] = {"name": name, "primitives": [primitive]}
        if targets:
            # Frame k's morph target: its POSITION (and NORMAL) minus the first frame's, in
            # float64 before rounding, one view per attribute over all targets.
            kinds = [("POSITION", "positions")]
            if first.normals is not None:
                kinds.append(("NORMAL", "normals"))
            morphs: list[dict[str, int]] = [{} for _ in range(targets)]
            for key, attribute in kinds:
                base = getattr(first, attribute)
                deltas = [
                    np.ascontiguousarray(getattr(g[name], attribute) - base, dtype=np.float32)
                    for g in geometry[1:]
                ]
                if any(d.shape != base.shape for d in deltas):
                    raise JellysimError(f"glTF export: {name} changes its vertex count")
                delta_view = built.view(b"".join(d.tobytes() for d in deltas), _ARRAY_BUFFER, 12)
                for k, delta in enumerate(deltas):
                    morphs[k][key] = built.accessor(
                        delta_view, k * delta.nbytes, delta, "VEC3", bounds=key == "POSITION"
                    )
            primitive["targets"] = morphs
            mesh["weights"] = [0.0] * targets
            mesh["extras"] = {"targetNames": target_names}
        meshes.append(mesh)
        nodes.append({"name": name, "mesh": len(meshes) - 1})

    # Keyframes at each frame's time, and one frame interval after the last (its hold); STEP.
    times = (np.asarray(frames, dtype=np.float64) / source.fps).astype(np.float32)
    times = np.append(times, times[-1] + np.float32(every / source.fps))
    samplers: list[dict[str, Any]] = []
    channels: list[dict[str, Any]] = []
    fluid_hides = "fluid" in names and not all(g["fluid"].shown for g in geometry)
    keys = -1  # the keyframe times' accessor, written where a channel uses it
    if targets or fluid_hides:
        keys = built.accessor(built.view(times.tobytes()), 0, times, "SCALAR", bounds=True)
    if targets:
        weights = np.zeros((len(times), targets), dtype=np.float32)
        weights[np.arange(1, targets + 1), np.arange(targets)] = 1.0  # frame k from its time
        weights[-1] = weights[-2]  # the last frame held
        output = built.accessor(built.view(weights.tobytes()), 0, weights.ravel(), "SCALAR")
        samplers.append({"input": keys, "output": output, "interpolation": "STEP"})
        for node_index in range(1, len(names) + 1):
            channels.append({"sampler": 0, "target": {"node": node_index, "path": "weights"}})
    if fluid_hides:
        shown = np.array([g["fluid"].shown for g in geometry] + [geometry[-1]["fluid"].shown])
        scales = np.repeat(shown.astype(np.float32), 3).reshape(-1, 3)
        output = built.accessor(built.view(scales.tobytes()), 0, scales, "VEC3")
        samplers.append({"input": keys, "output": output, "interpolation": "STEP"})
        fluid_node = 1 + names.index("fluid")
        channels.append(
            {"sampler": len(samplers) - 1, "target": {"node": fluid_node, "path": "scale"}}
        )
        if not shown[0]:
            nodes[fluid_node - 1]["scale"] = [0.0, 0.0, 0.0]

    root = {"name": source.name, "children": list(range(1, len(nodes) + 1))}
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
        "scenes": [
            {
                "name": source.name,
                "nodes": [0],
                # Blender's importer keeps these as custom properties of its scene;
                # export_gltf adds the Blender script's settings under "jellysim".
                "extras": {
                    "fps": source.fps,
                    "frame_start": frames[0],
                    "frame_end": frames[-1],
                    "frame_step": every,
                },
            }
        ],
        "nodes": [root, *nodes],
        "meshes": meshes,
        "materials": materials,
        "animations": [{"name": source.name, "channels": channels, "samplers": samplers}],
        "accessors": built.accessors,
        "bufferViews": built.buffer_views,
        "buffers": [{"byteLength": built.length}],
    }
    if not channels:
        del document["animations"]
    for key in ("meshes", "materials"):
        if not document[key]:
            del document[key]
    return document, built.chunks, _world_box(geometry)


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
    """Write ``frames`` as ``OUT/<name>_partNNN.glb``, the index ``OUT/<name>.gltf-parts.json``
    and the Blender import script ``OUT/import_into_blender.py`` (the first part's settings
    embedded); returns the parts, the index, then the script. ``budget``: bytes per part
    (``PART_BUDGET_BYTES``)."""
    source = _read(result, interpolation, frames)
    every = frames.step
    runs = _plan_parts(source, frames, PART_BUDGET_BYTES if budget is None else budget)
    camera = camera_path(result, interpolation)
    paths = []
    entries = []
    first_settings: dict[str, Any] = {}
    for part, run in enumerate(runs):
        path = out / f"{source.name}_part{part:03d}.glb"
        document, binary, (low, high) = _build_part(source, run, every, part, len(runs))
        settings = blender_settings(
            result.scene, run, source.fps, low, high, path.name, source.groups, camera
        )
        document["scenes"][0]["extras"]["jellysim"] = settings
        first_settings = first_settings or settings
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
    return [*paths, index_path, write_blender_script(out / BLENDER_SCRIPT, first_settings)]
