"""Oral arms drawn as frilled, ruffled curtains (issue 25, the paper's Fig. 13): a ribbon swept
along a simulated chain, its free edges waving out of the ribbon's plane.

Pure geometry and the renderers' primitives; docs/theory/ribbons.md numbers the equations
(R1-R6). A chain is a centreline (P, 3) m, root first, in world coordinates (z up); a padded
result's trailing NaN rows are dropped. Every array is float64 unless said otherwise.

- :func:`ribbon_frames`: a twist-free (rotation-minimising) frame along a centreline whose width
  direction starts along an ``outward`` hint (Eq. R2).
- :func:`ribbon_mesh`: the ruffled ribbon as a triangle mesh with vertex normals (Eq. R3-R6).
- :func:`povray_ribbons`: many ribbons as one POV-Ray ``mesh2`` in the tissue of the bell.
- :func:`ribbon_primitives`: their triangles for the preview renderer.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from jellysim.render.frame import RGB, Look
from jellysim.render.materials import GLOW_EMISSION, bell_transmit
from jellysim.render.povray import FRESNEL_SAMPLES
from jellysim.render.preview import (
    AMBIENT,
    Primitives,
    View,
    empty_primitives,
    key_light,
    project,
    visible,
)

ROWS = 9  # vertex rows across a ribbon (odd: the middle one lies on the centreline)
SUBDIVISIONS = 2  # at least this many centreline stations per particle segment (Eq. R1)
STATIONS_PER_RUFFLE = 8  # and at least this many per ruffle wavelength
FOLD = 0.4  # the curtain's fold: at a pleat's crest the edges stand this much of the width out
PLEAT_WIDTHS = 1.5  # a pleat (half a wave of the fold, Eq. R4) is this many root widths long
RUFFLE_ROOT = 0.4  # the ruffles' amplitude at the root, fraction of that at the tip (Eq. R5)
EDGE_POWER = 3.0  # the ruffles' amplitude grows as |across|^EDGE_POWER from the centre line
EDGE_PHASE = 0.5 * math.pi  # rad: the two edges ruffle this far out of phase
SCALLOP = 0.2  # an edge also moves in plane, this fraction of its out-of-plane amplitude
MEANDER = 1.0  # rad: the ruffles' phase wanders by this much, so they are not all alike,
MEANDER_WAVES = 3.7  # over this many ruffle wavelengths,
MEANDER_PHASE = 2.399963  # shifted by this multiple of the ribbon's phase (the golden angle)


class RibbonFrames(NamedTuple):
    """Unit vectors (P, 3) at each centreline point: ``tangent`` along the chain (root to tip),
    ``width`` across the ribbon, ``binormal = tangent x width`` out of its plane."""

    tangent: np.ndarray
    width: np.ndarray
    binormal: np.ndarray


class RibbonMesh(NamedTuple):
    """A triangle mesh: ``vertices`` (V, 3) m, ``faces`` (M, 3) int32 (one consistent winding),
    ``normals`` (V, 3) unit, on the side the winding makes the front."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray


def empty_mesh() -> RibbonMesh:
    return RibbonMesh(np.empty((0, 3)), np.empty((0, 3), dtype=np.int32), np.empty((0, 3)))


def finite_chain(centreline: np.ndarray) -> np.ndarray:
    """The chain's points (P', 3) m up to its first non-finite row (a padded result's trailing
    NaN rows), without points that repeat their predecessor (closer than 1e-9 of the chain's
    longest segment, or exactly equal)."""
    points = np.asarray(centreline, dtype=np.float64).reshape(-1, 3)
    finite = np.isfinite(points).all(axis=1)
    end = int(np.argmin(finite)) if not finite.all() else len(points)
    points = points[:end]
    if len(points) < 2:
        return points
    step = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return points[np.concatenate([[True], step > 1e-9 * step.max()])]


def _unit(vectors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors of ``vectors`` (..., 3) and their lengths (...,); zero vectors stay zero."""
    length = np.linalg.norm(vectors, axis=-1)
    return vectors / np.where(length > 0.0, length, 1.0)[..., None], length


def _perpendicular(tangent: np.ndarray, hint: np.ndarray) -> np.ndarray:
    """``hint`` made perpendicular to the unit ``tangent`` and unit; where it is (nearly)
    parallel to the tangent, the world axis least aligned with the tangent instead."""
    width, length = _unit(hint - (hint @ tangent) * tangent)
    if length > 1e-6 * max(float(np.linalg.norm(hint)), 1e-300):
        return width
    axis = np.zeros(3)
    axis[int(np.argmin(np.abs(tangent)))] = 1.0
    return _unit(axis - (axis @ tangent) * tangent)[0]


def ribbon_frames(centreline: np.ndarray, outward: np.ndarray) -> RibbonFrames:
    """The rotation-minimising (Bishop) frame along ``centreline`` (P >= 2, 3) m, its width
    direction starting along ``outward`` (3,) made perpendicular to the first tangent.

    Tangents are central differences (one-sided at the ends), a zero one replaced by its
    predecessor's; the width direction is carried from point to point by the double reflection
    of Wang et al. (2008), Eq. (R2), which turns it without twist about the tangent."""
    points = np.asarray(centreline, dtype=np.float64)
    count = len(points)
    tangent, length = _unit(np.gradient(points, axis=0))
    valid = length > 0.0  # not where the chain stops, or doubles back on itself
    if not valid.any():  # every point the same: any direction will do
        tangent[:] = np.array([0.0, 0.0, -1.0])
    else:  # the last valid tangent at or before each point; the first valid before it
        first = int(np.argmax(valid))
        tangent = tangent[np.maximum.accumulate(np.where(valid, np.arange(count), first))]
    width = np.empty_like(points)
    width[0] = _perpendicular(tangent[0], np.asarray(outward, dtype=np.float64))
    for i in range(count - 1):
        r, t = width[i], tangent[i]
        v1 = points[i + 1] - points[i]
        c1 = v1 @ v1
        if c1 > 0.0:  # reflect in the plane bisecting the two points
            r = r - (2.0 / c1) * (v1 @ r) * v1
            t = t - (2.0 / c1) * (v1 @ t) * v1
        v2 = tangent[i + 1] - t
        c2 = v2 @ v2
        if c2 > 0.0:  # reflect the reflected tangent onto the next one
            r = r - (2.0 / c2) * (v2 @ r) * v2
        width[i + 1] = _perpendicular(tangent[i + 1], r)
    return RibbonFrames(tangent, width, np.cross(tangent, width))


def catmull_rom(points: np.ndarray, subdivisions: int) -> np.ndarray:
    """The uniform Catmull-Rom curve through ``points`` (P, 3), ``subdivisions`` stations per
    segment, (subdivisions (P - 1) + 1, 3), Eq. (R1); the end tangents from mirrored ghost
    points, so a straight, evenly spaced chain stays straight and evenly spaced."""
    if subdivisions <= 1 or len(points) < 2:
        return points
    padded = np.concatenate(
        [2.0 * points[:1] - points[1:2], points, 2.0 * points[-1:] - points[-2:-1]]
    )
    t = np.arange(subdivisions) / subdivisions
    # Basis of p_{i-1}, p_i, p_{i+1}, p_{i+2} at parameter t, (subdivisions, 4).
    basis = 0.5 * np.stack(
        [-(t**3) + 2 * t**2 - t, 3 * t**3 - 5 * t**2 + 2, -3 * t**3 + 4 * t**2 + t, t**3 - t**2],
        axis=1,
    )
    segments = len(points) - 1
    windows = np.stack([padded[k : k + segments] for k in range(4)], axis=1)  # (S, 4, 3)
    curve = np.einsum("tk,skc->stc", basis, windows).reshape(-1, 3)
    return np.concatenate([curve, points[-1:]])


def grid_faces(stations: int, rows: int) -> np.ndarray:
    """Two triangles per quad of a (stations, rows) vertex grid numbered ``i rows + j``,
    (2 (stations - 1)(rows - 1), 3) int32, all wound the same way."""
    i, j = np.meshgrid(np.arange(stations - 1), np.arange(rows - 1), indexing="ij")
    a = (i * rows + j).ravel()
    b, c, d = a + rows, a + rows + 1, a + 1
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int32)


def stations_per_segment(points: np.ndarray, ruffles: float, subdivisions: int) -> int:
    """Centreline stations per particle segment of a ribbon along ``points`` (P, 3) m, Eq.
    (R1): at least ``subdivisions``, and ``STATIONS_PER_RUFFLE`` per ruffle wavelength
    (``ruffles`` per m) over its longest segment."""
    segment = float(np.linalg.norm(np.diff(points, axis=0), axis=1).max())
    return max(int(subdivisions), math.ceil(STATIONS_PER_RUFFLE * abs(ruffles) * segment))


def ribbon_mesh(
    centreline: np.ndarray,
    outward: np.ndarray,
    width: float,
    taper: float,
    ruffles: float,
    ruffle_depth: float,
    phase: float = 0.0,
    across: int = ROWS,
    fold: float = FOLD,
    subdivisions: int = SUBDIVISIONS,
) -> RibbonMesh:
    """A ruffled ribbon along ``centreline`` (P, 3) m, root first (trailing NaN rows dropped).

    ``width`` (m) at the root, narrowing linearly to ``taper width`` at the tip (R3); the width
    direction starts along ``outward`` (3,) (for an oral arm, radially out from the bell axis)
    and is transported along the chain (R2). Out of the ribbon's plane the surface has curtain
    pleats, the edges standing up to ``fold`` of the local width out, the fold changing side
    every ``PLEAT_WIDTHS`` root widths (R4), and ruffles (R5): ``ruffles`` waves per metre of
    arm at the edges, out of plane ``ruffle_depth`` of the local width at the tip's edges (from
    ``RUFFLE_ROOT`` of that at the root), growing as ``|across|^EDGE_POWER`` from the centre
    line, the two edges ``EDGE_PHASE`` apart, the whole pattern shifted by ``phase`` (rad) so
    that arms do not ruffle in lockstep; in plane the edges scallop by ``SCALLOP`` of that
    amplitude. ``across`` vertex rows across; the centreline is
    smoothed to at least ``subdivisions`` stations per particle segment and
    ``STATIONS_PER_RUFFLE`` per ruffle (R1). Normals from the surface's parameter derivatives
    (R6). Fewer than two distinct finite points: an empty mesh.
    """
    points = finite_chain(centreline)
    if len(points) < 2:
        return empty_mesh()
    across = max(int(across), 2)
    curve = catmull_rom(points, stations_per_segment(points, ruffles, subdivisions))
    frames = ribbon_frames(curve, outward)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
    u = arc / arc[-1]  # (S,) 0 at the root, 1 at the tip
    half = 0.5 * width * (1.0 - (1.0 - taper) * u)  # (S,) m, Eq. (R3)
    a = np.linspace(-1.0, 1.0, across)  # (A,) across: -1 one edge, +1 the other
    along = 2.0 * math.pi * ruffles * arc[:, None]  # (S, 1) rad
    pleat = np.cos(math.pi * arc / (PLEAT_WIDTHS * max(width, 1e-300)) + phase)  # (S,)
    wave = (
        along
        + phase
        + EDGE_PHASE * (a > 0.0)
        + MEANDER * np.sin(along / MEANDER_WAVES + MEANDER_PHASE * phase)
    )  # (S, A) rad
    growth = RUFFLE_ROOT + (1.0 - RUFFLE_ROOT) * u  # (S,)
    ruffle = ruffle_depth * growth[:, None] * np.abs(a) ** EDGE_POWER  # (S, A) of the width
    # Out of plane (along the binormal) and in plane (along the width), m, Eq. (R4-R5).
    out_of_plane = (2.0 * half)[:, None] * (fold * pleat[:, None] * a**2 + ruffle * np.sin(wave))
    across_offset = half[:, None] * (a + SCALLOP * np.sign(a) * ruffle * np.cos(wave))
    vertices = (
        curve[:, None, :]
        + across_offset[..., None] * frames.width[:, None, :]
        + out_of_plane[..., None] * frames.binormal[:, None, :]
    )  # (S, A, 3)
    # Eq. (R6): n = X_s x X_a, the front the side the faces' winding makes the front.
    normals = np.cross(np.gradient(vertices, axis=0), np.gradient(vertices, axis=1))
    normals, length = _unit(normals)
    fallback = np.broadcast_to(frames.binormal[:, None, :], normals.shape)
    normals = np.where((length > 0.0)[..., None], normals, fallback)
    faces = grid_faces(len(curve), across)
    flat = vertices.reshape(-1, 3)
    corner = flat[faces]
    area = np.linalg.norm(
        np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0]), axis=1
    )
    faces = faces[area > 1e-12 * max(float(arc[-1]) * max(width, 1e-300), 1e-300)]
    return RibbonMesh(flat, faces, normals.reshape(-1, 3))


def _vectors(values: np.ndarray, digits: int) -> str:
    """World vectors (V, 3) as POV-Ray vectors ``<x,z,y>`` (y up, left-handed) of ``digits``
    significant digits, comma-joined; one format string for all, no loop per vertex."""
    swapped = np.ascontiguousarray(values[:, [0, 2, 1]], dtype=np.float64)
    one = f"<%.{digits}g,%.{digits}g,%.{digits}g>"
    return ",".join([one] * len(swapped)) % tuple(swapped.ravel().tolist())


def _indices(faces: np.ndarray) -> str:
    return ",".join(["<%d,%d,%d>"] * len(faces)) % tuple(faces.ravel().tolist())


def ribbon_pigment(color: RGB, look: Look) -> str:
    """The ribbon's tissue over POV-Ray's ``aoi`` pattern, as the bell's: ``look``'s
    transparency face-on, its Fresnel-like rim (:func:`bell_transmit`) towards the silhouette,
    both sides alike (a thin sheet), in ``color``."""
    base = np.asarray(color, dtype=np.float64)
    entries = []
    for fraction in FRESNEL_SAMPLES:
        transmit, lighten = bell_transmit(look, math.cos(0.5 * math.pi * fraction))
        rgb = base + float(lighten) * (1.0 - base)
        pigment = f"rgbt <{rgb[0]:.4g},{rgb[1]:.4g},{rgb[2]:.4g},{float(transmit):.3g}>"
        # aoi: 1 face-on, 0.5 at the silhouette, 0 face-on again from behind.
        for value in sorted({0.5 * fraction, 1.0 - 0.5 * fraction}):
            entries.append((value, pigment))
    entries.sort(key=lambda entry: entry[0])
    return "aoi pigment_map { " + " ".join(f"[{v:.4g} {p}]" for v, p in entries) + " }"


def povray_ribbons(meshes: Sequence[RibbonMesh], color: RGB, look: Look, glow: bool = False) -> str:
    """Every ribbon of one jellyfish in one POV-Ray ``mesh2`` (world coordinates through the
    y-z swap of :func:`jellysim.render.povray.vec`; POV-Ray does not cull, so the winding may
    reverse), in ``color`` with ``look``'s transparency and rim (:func:`ribbon_pigment`) and,
    with ``glow`` (final quality), the bell's emission ``GLOW_EMISSION look.glow``. "" when
    every mesh is empty."""
    meshes = [mesh for mesh in meshes if len(mesh.faces)]
    if not meshes:
        return ""
    offsets = np.cumsum([0] + [len(mesh.vertices) for mesh in meshes[:-1]])
    vertices = np.concatenate([mesh.vertices for mesh in meshes])
    normals = np.concatenate([mesh.normals for mesh in meshes])
    faces = np.concatenate(
        [mesh.faces + offset for mesh, offset in zip(meshes, offsets, strict=True)]
    )
    finish = "finish { ambient 0.1 diffuse 0.55 specular 0.35 roughness 0.01"
    finish += f" emission {GLOW_EMISSION * look.glow:.3g} }}" if glow else " }"
    return (
        "mesh2 {\n"
        f"  vertex_vectors {{ {len(vertices)},\n{_vectors(vertices, 6)}\n  }}\n"
        f"  normal_vectors {{ {len(normals)},\n{_vectors(normals, 4)}\n  }}\n"
        f"  face_indices {{ {len(faces)},\n{_indices(faces)}\n  }}\n"
        f"  texture {{ pigment {{ {ribbon_pigment(color, look)} }} {finish} }}\n"
        "}\n"
    )


def ribbon_primitives(
    meshes: Sequence[RibbonMesh], color: RGB, look: Look, view: View, near: float
) -> Primitives:
    """The ribbons' triangles for the preview renderer (corners padded to a quadrilateral by
    repeating the last), shaded as the bell's are: Lambert with two-sided normals plus
    ``AMBIENT``, opacity and lightening from :func:`bell_transmit` at the face's angle to the
    camera, in ``color``."""
    meshes = [mesh for mesh in meshes if len(mesh.faces)]
    if not meshes:
        return empty_primitives()
    parts = []
    for mesh in meshes:
        pixels, depth = project(mesh.vertices, view)
        keep = visible(pixels[mesh.faces], depth[mesh.faces], view, near)
        faces = mesh.faces[keep]
        normal = mesh.normals[faces].sum(axis=1)
        centroid = mesh.vertices[faces].mean(axis=1)
        parts.append((pixels[faces], normal, centroid))
    corners = np.concatenate([part[0] for part in parts])
    normal = np.concatenate([part[1] for part in parts])
    centroid = np.concatenate([part[2] for part in parts])
    to_camera = view.location - centroid
    distance = np.linalg.norm(to_camera, axis=1)
    normal *= np.where(np.einsum("ij,ij->i", normal, to_camera) < 0.0, -1.0, 1.0)[:, None]
    normal = _unit(normal)[0]
    brightness = AMBIENT + (1.0 - AMBIENT) * np.clip(normal @ key_light(view), 0.0, 1.0)
    cos_theta = np.einsum("ij,ij->i", normal, to_camera) / np.where(distance > 0, distance, 1.0)
    transmit, lighten = bell_transmit(look, cos_theta)
    base = np.asarray(color, dtype=np.float64)
    rgb = (base + lighten[:, None] * (1.0 - base)) * brightness[:, None]
    return Primitives(
        corners=np.concatenate([corners, corners[:, 2:]], axis=1),
        rgba=np.column_stack([rgb, 1.0 - transmit]),
        distance=distance,
    )
