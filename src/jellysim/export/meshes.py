"""Frame sequences for tools that read plain meshes: Wavefront OBJ and binary PLY.

- ``obj``: ``frame_NNNNN.obj`` per frame: object ``bell`` (its vertices and triangles, counter-
  clockwise seen from outside) and object ``tentacles`` (every drawn tentacle as one polyline,
  ``l`` elements). Blender, Houdini and most 3-D tools import OBJ sequences.
- ``ply``: ``frame_NNNNN.ply`` per frame (binary): for a fluid, the live particles as a point
  cloud with ``pressure``, ``velocity`` (vx, vy, vz) and ``kind``; otherwise the bell's triangles
  and every drawn tentacle's particles, with ``part`` (0 bell, 1 tentacle) per point.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jellysim import fields
from jellysim.io.result import Result


def _drawn(result: Result, interpolation: int | None) -> np.ndarray | None:
    if not result.has(fields.TENTACLE_POSITION):
        return None
    from jellysim.interpolation import interpolate_result

    return interpolate_result(result, interpolation)


def _bell(result: Result, frame: int) -> tuple[np.ndarray, np.ndarray] | None:
    if not result.has(fields.BELL_SURFACE_VERTICES):
        return None
    return (
        result.read(fields.BELL_SURFACE_VERTICES, frame).astype(np.float64),
        result.bell_surface_faces.astype(np.int64),
    )


def write_obj(
    path: Path,
    time: float,
    bell: tuple[np.ndarray, np.ndarray] | None,
    tentacles: np.ndarray | None,
) -> None:
    """One frame as an OBJ file (1-based indices; written to a temporary name, then renamed)."""
    lines = [f"# jellysim frame at t = {time:.9g} s (m, z up)"]
    offset = 1
    if bell is not None:
        vertices, faces = bell
        lines.append("o bell")
        lines += [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in vertices]
        lines += [f"f {a + offset} {b + offset} {c + offset}" for a, b, c in faces]
        offset += len(vertices)
    if tentacles is not None and tentacles.size:
        count, particles, _ = tentacles.shape
        lines.append("o tentacles")
        lines += [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in tentacles.reshape(-1, 3)]
        for k in range(count):
            first = offset + k * particles
            lines.append("l " + " ".join(str(first + i) for i in range(particles)))
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text("\n".join(lines) + "\n", encoding="ascii")
    temporary.replace(path)


def export_obj(
    result: Result, out: Path, frames: range, interpolation: int | None = None
) -> list[Path]:
    drawn = _drawn(result, interpolation)
    times = result.time
    paths = []
    for frame in frames:
        path = out / f"frame_{frame:05d}.obj"
        write_obj(
            path, float(times[frame]), _bell(result, frame), None if drawn is None else drawn[frame]
        )
        paths.append(path)
    return paths[:1]


def export_ply(
    result: Result, out: Path, frames: range, interpolation: int | None = None
) -> list[Path]:
    import meshio

    drawn = _drawn(result, interpolation)
    # The particle kinds of a fluid, read once (None: no fluid, the bell and tentacles instead).
    kind = result.fluid_kind.astype(np.int32) if result.has(fields.FLUID_POSITION) else None
    paths = []
    for frame in frames:
        if kind is not None:
            alive = result.read(fields.FLUID_ALIVE, frame)
            points = result.read(fields.FLUID_POSITION, frame)[alive]
            velocity = result.read(fields.FLUID_VELOCITY, frame)[alive]
            padded = np.zeros((len(points), 3))
            padded[:, : points.shape[1]] = points
            point_data = {
                "pressure": result.read(fields.FLUID_PRESSURE, frame)[alive],
                "kind": kind[alive],
            }
            for k, name in enumerate("xyz"[: velocity.shape[1]]):
                point_data[f"v{name}"] = velocity[:, k]
            mesh = meshio.Mesh(padded, [], point_data=point_data)
        else:
            parts, cells, part_ids = [], [], []
            bell = _bell(result, frame)
            if bell is not None:
                parts.append(bell[0])
                cells.append(("triangle", bell[1].astype(np.int32)))
                part_ids.append(np.zeros(len(bell[0]), dtype=np.int32))
            if drawn is not None:
                parts.append(drawn[frame].reshape(-1, 3))
                part_ids.append(np.ones(parts[-1].shape[0], dtype=np.int32))
            mesh = meshio.Mesh(
                np.concatenate(parts), cells, point_data={"part": np.concatenate(part_ids)}
            )
        path = out / f"frame_{frame:05d}.ply"
        meshio.write(path, mesh, file_format="ply", binary=True)
        paths.append(path)
    return paths[:1]
