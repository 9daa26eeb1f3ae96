"""Frame sequences for tools that read plain meshes: Wavefront OBJ and binary PLY.

- ``obj``: ``frame_NNNNN.obj`` per frame: object ``bell`` (its vertices and triangles, counter-
  clockwise seen from outside) and an object per tentacle group (:mod:`jellysim.export.groups`):
  ``tentacles`` in a one-group scene; in a scene of several, ``tentacles_NAME`` holding the
  group ``g NAME`` in the material ``tentacles_NAME`` of ``materials.mtl`` (the group's colour,
  the bell's too). A thread group's drawn tentacles are closed tapered tubes (the glTF export's,
  ``TUBE_SIDES`` around, triangles with vertex normals: edges would not render), a ribbon
  group's arms triangles with vertex normals (``vn``). ``up``: "y" (the default, the convention
  of OBJ readers: Blender's and trimesh's import read y as up) writes jellysim's (x, y, z) as
  (x, z, -y); "z" writes them as they are.
- ``ply``: ``frame_NNNNN.ply`` per frame (binary): for a fluid, the live particles as a point
  cloud with ``pressure``, ``velocity`` (vx, vy, vz) and ``kind``; otherwise the bell's triangles
  and every drawn tentacle's particles (each of its group's own count), with ``part`` (0 bell,
  1 tentacle) per point.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jellysim import fields
from jellysim.export.gltf import tube_faces, tube_vertices
from jellysim.export.groups import ExportGroup, export_groups
from jellysim.io.result import Result
from jellysim.render.materials import Material, bell_material

MATERIALS = "materials.mtl"  # the materials of a scene of several tentacle groups


def to_up(vectors: np.ndarray, up: str) -> np.ndarray:
    """jellysim's z-up (x, y, z) as the file's axes: unchanged for "z", (x, z, -y) for "y" (a
    rotation by -90 degrees about x, so handedness and winding are kept)."""
    if up == "z":
        return vectors
    return np.stack([vectors[:, 0], vectors[:, 2], -vectors[:, 1]], axis=1)


def _groups(result: Result, interpolation: int | None) -> list[ExportGroup]:
    from jellysim.render.pipeline import scene_look

    return export_groups(result, scene_look(result.scene), interpolation)


def _bell(result: Result, frame: int) -> tuple[np.ndarray, np.ndarray] | None:
    if not result.has(fields.BELL_SURFACE_VERTICES):
        return None
    return (
        result.read(fields.BELL_SURFACE_VERTICES, frame).astype(np.float64),
        result.bell_surface_faces.astype(np.int64),
    )


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit normals (V, 3) at ``vertices``: the area-weighted sum of their triangles' normals
    (counter-clockwise faces point them outwards); a vertex in no triangle gets +z."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)  # length: twice the area
    summed = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(summed, faces[:, k], face)
    length = np.linalg.norm(summed, axis=1, keepdims=True)
    return np.where(length > 0.0, summed / np.maximum(length, 1e-300), [0.0, 0.0, 1.0])


def write_mtl(path: Path, materials: list[Material]) -> None:
    """``materials`` as a Wavefront MTL file: diffuse ``Kd`` and emission ``Ke`` (linear RGB),
    dissolve ``d`` (the opacity), optical density ``Ni`` (the index of refraction) and the PBR
    extension's roughness ``Pr`` (Blender's OBJ importer reads all five; older tools read
    ``Kd`` and ``d``)."""
    lines = ["# jellysim materials (linear RGB)"]
    for material in materials:
        lines += [
            f"newmtl {material.name}",
            "Kd {:.6g} {:.6g} {:.6g}".format(*material.base_color),
            "Ke {:.6g} {:.6g} {:.6g}".format(*material.emissive),
            f"d {material.opacity:.6g}",
            f"Ni {material.ior:.6g}",
            f"Pr {material.roughness:.6g}",
        ]
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text("\n".join(lines) + "\n", encoding="ascii")
    temporary.replace(path)


def _mesh_lines(
    vertices: np.ndarray, normals: np.ndarray, faces: np.ndarray, offset: int, up: str
) -> list[str]:
    """A mesh's ``v``, ``vn`` and ``f v//vn`` lines, its vertices numbered from ``offset`` (its
    normals too: one normal per vertex)."""
    assert len(normals) == len(vertices)
    lines = [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in to_up(vertices, up)]
    lines += [f"vn {x:.6g} {y:.6g} {z:.6g}" for x, y, z in to_up(normals, up)]
    lines += [
        f"f {a + offset}//{a + offset} {b + offset}//{b + offset} {c + offset}//{c + offset}"
        for a, b, c in faces
    ]
    return lines


def write_obj(
    path: Path,
    time: float,
    bell: tuple[np.ndarray, np.ndarray] | None,
    groups: list[ExportGroup],
    frame: int,
    materials: str | None = None,
    up: str = "y",
) -> None:
    """Frame ``frame`` as an OBJ file (1-based indices; written to a temporary name, then
    renamed). ``materials``: the MTL file the objects' ``usemtl`` names (None: none named);
    ``up``: the file's up axis (:func:`to_up`)."""
    lines = [f"# jellysim frame at t = {time:.9g} s (m, {up} up)"]
    if materials is not None:
        lines.append(f"mtllib {materials}")
    offset = 1  # every vertex has its normal, at the same index
    if bell is not None:
        vertices, faces = bell
        lines.append("o bell")
        if materials is not None:
            lines.append("usemtl bell")
        normals = vertex_normals(vertices, faces)  # smooth shading, and a normal per vertex
        lines += _mesh_lines(vertices, normals, faces, offset, up)
        offset += len(vertices)
    for group in groups:
        tentacles = group.positions[frame]
        if not tentacles.size:
            continue
        lines.append(f"o {group.part}")
        if materials is not None:
            lines += [f"g {group.name}", f"usemtl {group.material.name}"]
        if group.ribbon:
            vertices, faces, normals, _ = group.ribbon_meshes(frame)
        else:  # threads as tubes: an OBJ line renders nowhere
            count, particles, _ = tentacles.shape
            vertices, normals = tube_vertices(tentacles, group.radii)
            faces = tube_faces(count, particles)
        lines += _mesh_lines(vertices, normals, faces, offset, up)
        offset += len(vertices)
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text("\n".join(lines) + "\n", encoding="ascii")
    temporary.replace(path)


def export_obj(
    result: Result, out: Path, frames: range, interpolation: int | None = None, up: str = "y"
) -> list[Path]:
    groups = _groups(result, interpolation)
    materials = None
    if len(groups) > 1:
        from jellysim.render.pipeline import scene_look

        materials = MATERIALS
        write_mtl(
            out / MATERIALS,
            [bell_material(scene_look(result.scene)), *(group.material for group in groups)],
        )
    times = result.time
    paths = []
    for frame in frames:
        path = out / f"frame_{frame:05d}.obj"
        write_obj(path, float(times[frame]), _bell(result, frame), groups, frame, materials, up)
        paths.append(path)
    return paths[:1]


def export_ply(
    result: Result, out: Path, frames: range, interpolation: int | None = None
) -> list[Path]:
    import meshio

    groups = _groups(result, interpolation)
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
            for group in groups:
                parts.append(group.positions[frame].reshape(-1, 3))
                part_ids.append(np.ones(parts[-1].shape[0], dtype=np.int32))
            mesh = meshio.Mesh(
                np.concatenate(parts), cells, point_data={"part": np.concatenate(part_ids)}
            )
        path = out / f"frame_{frame:05d}.ply"
        meshio.write(path, mesh, file_format="ply", binary=True)
        paths.append(path)
    return paths[:1]
