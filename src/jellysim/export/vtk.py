"""VTK export for ParaView: one VTU file per frame and part, indexed by a ``.pvd`` per part.

Parts (each present only when the result has it):

- ``fluid``: the live fluid particles as vertex cells, with ``pressure`` (Pa), ``velocity``
  (m/s, 3 components), ``number_density`` and ``kind`` (0 fluid, 1 wall, 2 dummy) and the
  particle's index in the result (``particle``). A 2-D fluid's (x, y) is written as (x, y, 0).
- ``tentacles``: every drawn tentacle (cosine interpolation) as line segments, with the index of
  the drawn tentacle (``tentacle``) and the particle's distance from the root (``arc_length``, m).
  A scene of several tentacle groups (:mod:`jellysim.export.groups`) writes a part
  ``tentacles_NAME`` per group instead, each with the cell array ``group`` (the group's index in
  the result's ``tentacle_groups``): a thread group as above, each tentacle of the group's own
  particle count; a ribbon group (oral arms) as its ruffled ribbons' triangles with
  ``Normals`` and ``tentacle`` (the arm) per point.
- ``bell``: the bell's surface triangles.
- ``bell_particles`` (a mass-spring bell): its particles as points with ``velocity`` (m/s) and
  ``particle`` (index in ``bell/position``), and its springs as line cells with ``muscle`` (1 for
  a circular-muscle spring) and ``rest_length`` (m, the length at the start).

Files: ``OUT/<part>_NNNNN.vtu`` and ``OUT/<part>.pvd`` (open the ``.pvd`` in ParaView: a time
series at the result's frame times).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from jellysim import fields
from jellysim.export.groups import ExportGroup, export_groups
from jellysim.io.result import Result


def _write_pvd(path: Path, entries: list[tuple[float, str]]) -> Path:
    lines = [
        '<?xml version="1.0"?>',
        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
        "  <Collection>",
        *(
            f'    <DataSet timestep="{time!r}" group="" part="0" file={quoteattr(name)}/>'
            for time, name in entries
        ),
        "  </Collection>",
        "</VTKFile>",
    ]
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text("\n".join(lines) + "\n", encoding="utf-8")
    temporary.replace(path)
    return path


def _as_3d(points: np.ndarray) -> np.ndarray:
    if points.shape[-1] == 3:
        return points
    padded = np.zeros((*points.shape[:-1], 3))
    padded[..., : points.shape[-1]] = points
    return padded


def fluid_mesh(result: Result, frame: int) -> Any:
    """The fluid particles alive at ``frame`` as a meshio Mesh of vertex cells."""
    import meshio

    position = result.read(fields.FLUID_POSITION, frame).astype(np.float64)
    alive = (
        result.read(fields.FLUID_ALIVE, frame)
        if result.has(fields.FLUID_ALIVE)
        else np.ones(position.shape[0], dtype=bool)
    )
    index = np.nonzero(alive)[0]
    point_data: dict[str, np.ndarray] = {"particle": index.astype(np.int64)}
    if result.has(fields.FLUID_VELOCITY):
        point_data["velocity"] = _as_3d(result.read(fields.FLUID_VELOCITY, frame)[index])
    for name, field in (
        ("pressure", fields.FLUID_PRESSURE),
        ("number_density", fields.FLUID_NUMBER_DENSITY),
    ):
        if result.has(field):
            point_data[name] = result.read(field, frame).astype(np.float64)[index]
    if result.has(fields.FLUID_KIND):
        point_data["kind"] = result.fluid_kind.astype(np.int32)[index]
    cells = [("vertex", np.arange(index.size, dtype=np.int64)[:, None])]
    return meshio.Mesh(_as_3d(position[index]), cells, point_data=point_data)


def tentacle_mesh(drawn: np.ndarray, spacing: float) -> Any:
    """Drawn tentacles (N, P, 3) as a meshio Mesh of line segments."""
    import meshio

    count, particles, _ = drawn.shape
    ids = np.arange(count * particles).reshape(count, particles)
    segments = np.stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()], axis=1)
    return meshio.Mesh(
        drawn.reshape(-1, 3),
        [("line", segments.astype(np.int64))],
        point_data={
            "tentacle": np.repeat(np.arange(count), particles).astype(np.int32),
            "arc_length": np.tile(spacing * np.arange(particles), count),
        },
    )


def group_mesh(group: ExportGroup, frame: int, spacing: float) -> Any:
    """One group of a scene of several at ``frame``: its threads' line segments
    (:func:`tentacle_mesh`) or its arms' ribbon triangles, with the cell array ``group``."""
    import meshio

    if not group.ribbon:
        mesh = tentacle_mesh(group.positions[frame], spacing)
    else:
        arms = group.ribbon_meshes(frame)
        mesh = meshio.Mesh(
            arms.vertices,
            [("triangle", arms.faces)],
            point_data={"Normals": arms.normals, "tentacle": arms.arm},
        )
    cells = len(mesh.cells[0].data)
    mesh.cell_data["group"] = [np.full(cells, group.index, dtype=np.int32)]
    return mesh


def bell_mesh(result: Result, frame: int) -> Any:
    import meshio

    vertices = result.read(fields.BELL_SURFACE_VERTICES, frame).astype(np.float64)
    faces = result.bell_surface_faces.astype(np.int64)
    return meshio.Mesh(vertices, [("triangle", faces)])


def bell_particle_mesh(result: Result, frame: int) -> Any:
    """The mass-spring bell at ``frame``: particles joined by their springs (line cells)."""
    import meshio

    position = result.read(fields.BELL_POSITION, frame).astype(np.float64)
    pairs = result.bell_springs.astype(np.int64)
    rest = result.bell_rest_positions.astype(np.float64)
    return meshio.Mesh(
        position,
        [("line", pairs)],
        point_data={
            "particle": np.arange(len(position), dtype=np.int64),
            "velocity": result.read(fields.BELL_VELOCITY, frame).astype(np.float64),
        },
        cell_data={
            "muscle": [result.bell_muscle.astype(np.int32)],
            "rest_length": [np.linalg.norm(rest[pairs[:, 1]] - rest[pairs[:, 0]], axis=1)],
        },
    )


def export_vtk(
    result: Result, out: Path, frames: range, interpolation: int | None = None
) -> list[Path]:
    """Write the VTU time series of ``frames`` into ``out``; returns the ``.pvd`` files."""
    import meshio

    times = result.time
    from jellysim.render.pipeline import scene_look

    parts: dict[str, list[tuple[float, str]]] = {}
    groups = export_groups(result, scene_look(result.scene), interpolation)
    for frame in frames:
        meshes = {}
        if result.has(fields.FLUID_POSITION):
            meshes["fluid"] = fluid_mesh(result, frame)
        for group in groups:
            spacing = result.scene.groups[group.index].tentacles.spacing
            if len(groups) == 1:
                meshes[group.part] = tentacle_mesh(group.positions[frame], spacing)
            else:
                meshes[group.part] = group_mesh(group, frame, spacing)
        if result.has(fields.BELL_SURFACE_VERTICES):
            meshes["bell"] = bell_mesh(result, frame)
        if result.has(
            fields.BELL_SPRINGS
        ):  # a kinematic bell's bell/position is its surface (a link)
            meshes["bell_particles"] = bell_particle_mesh(result, frame)
        for part, mesh in meshes.items():
            name = f"{part}_{frame:05d}.vtu"
            meshio.write(out / name, mesh, file_format="vtu")
            parts.setdefault(part, []).append((float(times[frame]), name))
    return [_write_pvd(out / f"{part}.pvd", entries) for part, entries in parts.items()]
