"""Tentacles kept out of the bell's tissue (docs/theory/tentacle.md §8, Eq. T15-T17).

The paper's tentacles feel only water: nothing stops a chain from passing through the bell, and a
soft bell that draws its margin in sweeps its wall over the upper part of its own fringe (issue 26).
Here the bell's tissue is the closed shell every output draws (``bell/surface_vertices`` over
``bell/surface_faces``), moving linearly in time between the two frames around the step. After
each substep's projection a particle whose centre lies inside the shell (an odd number of the
shell's triangles above it, Eq. T15) is put back on the shell's surface where its path came in,
or at the surface's nearest point where the wall came over it (Eq. T16), a particle of a chain
with a prescribed root where the line from the root meets the surface if that tangent plane is
out of the chain's reach from the root (Eq. T16b); the kernel then projects
the chain's lengths again together with the wall's tangent plane at each particle put on it, so
that the chain slides along the wall, in rounds (Eq. T17,
:func:`jellysim.tentacle.kernels._keep_out`). The velocity from the displacement (Eq. T9) carries
the wall's normal velocity: an inelastic, frictionless contact. The bell does not feel it, as it
feels no other force of its tentacles (the paper's one-way coupling, §4.2.4).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

# Of the shell's size: the vertical ray of the parity test starts this far off the particle,
# sideways, so that it never runs exactly along a mesh edge (a chain hanging straight down at the
# angle of a mesh meridian would have its crossings of the edge's two triangles counted twice or
# not at all). The same offset as the check on stored results (tests/integration/
# test_nothing_through_the_bell.py).
RAY_NUDGE = (1.37e-9, 2.71e-9)
# Of the shell's size: how far beyond the surface a particle is put, so that it tests outside
# also against the single-precision vertices a result stores (whose rounding is below 1e-7 of the
# coordinates).
CLEARANCE = 1.0e-5
COORDINATE_CLEARANCE = 1.0e-6  # of the largest coordinate: 16 single-precision roundings
# Of the chain's length from a prescribed root to a particle: a tangent plane farther than this
# from the root is out of the particle's reach (Eq. T16b); nearer to the full length the chain
# would stand almost straight along the plane's normal, where the projection's system (Eq. T17)
# is close to singular.
ROOT_REACH = 0.99


class Obstacle(NamedTuple):
    """A closed triangle shell moving linearly in time over one frame.

    ``start``, ``end``: (V, 3) m, the vertices at the frame's start and end; ``faces`` (M, 3)
    their triangles (M = 0: no obstacle); ``lower``, ``upper`` (3,) m, a box holding the shell
    all through the frame; ``nudge`` (2,) m, the parity ray's sideways offset; ``clearance``
    m, how far beyond the surface a particle is put.
    """

    start: np.ndarray
    end: np.ndarray
    faces: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    nudge: np.ndarray
    clearance: float


def no_obstacle() -> Obstacle:
    """Nothing to keep out of: the paper's model."""
    empty = np.zeros((0, 3))
    return Obstacle(
        empty, empty, np.zeros((0, 3), np.int64), np.zeros(3), np.zeros(3), np.zeros(2), 0.0
    )


def shell_obstacle(start: np.ndarray, end: np.ndarray, faces: np.ndarray) -> Obstacle:
    """The shell with vertices ``start`` at the frame's start and ``end`` at its end."""
    start = np.ascontiguousarray(start, dtype=np.float64)
    end = np.ascontiguousarray(end, dtype=np.float64)
    lower = np.minimum(start.min(axis=0), end.min(axis=0))
    upper = np.maximum(start.max(axis=0), end.max(axis=0))
    size = float(np.max(upper - lower))
    # float32 rounding of the stored vertices grows with the coordinates, not with the shell
    reach = float(np.max(np.abs(np.concatenate((lower, upper)))))
    return Obstacle(
        start,
        end,
        np.ascontiguousarray(faces, dtype=np.int64),
        lower,
        upper,
        np.array(RAY_NUDGE) * size,
        max(CLEARANCE * size, COORDINATE_CLEARANCE * reach),
    )


@njit(cache=True)
def _vertex(obstacle: Obstacle, index: int, tau: float, out: np.ndarray) -> None:
    for k in range(3):
        a = obstacle.start[index, k]
        out[k] = a + tau * (obstacle.end[index, k] - a)


@njit(cache=True)
def _dot(u: np.ndarray, v: np.ndarray) -> float:
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


@njit(cache=True)
def _closest_on_triangle(
    p: np.ndarray, corners: np.ndarray, work: np.ndarray, out: np.ndarray
) -> float:
    """The point of the triangle ``corners`` (3, 3) nearest to ``p`` into ``out``; its squared
    distance. By the Voronoi regions of the triangle's vertices, edges and face (Ericson,
    Real-Time Collision Detection, 2005, §5.1.5). ``work`` (5, 3) is scratch."""
    a, b, c = corners[0], corners[1], corners[2]
    ab, ac, ap, bp, cp = work[0], work[1], work[2], work[3], work[4]
    for k in range(3):
        ab[k] = b[k] - a[k]
        ac[k] = c[k] - a[k]
        ap[k] = p[k] - a[k]
        bp[k] = p[k] - b[k]
        cp[k] = p[k] - c[k]
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    # (u, v): out = a + u ab + v ac
    if d1 <= 0.0 and d2 <= 0.0:
        u, v = 0.0, 0.0  # vertex a
    elif d3 >= 0.0 and d4 <= d3:
        u, v = 1.0, 0.0  # vertex b
    elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        u, v = d1 / (d1 - d3), 0.0  # edge ab
    elif d6 >= 0.0 and d5 <= d6:
        u, v = 0.0, 1.0  # vertex c
    elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        u, v = 0.0, d2 / (d2 - d6)  # edge ac
    elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))  # edge bc
        u, v = 1.0 - w, w
    else:
        denominator = 1.0 / (va + vb + vc)  # the face
        u, v = vb * denominator, vc * denominator
    distance2 = 0.0
    for k in range(3):
        out[k] = a[k] + u * ab[k] + v * ac[k]
        distance2 += (out[k] - p[k]) ** 2
    return distance2


@njit(cache=True)
def inside_shell(p: np.ndarray, obstacle: Obstacle, tau: float, corners: np.ndarray) -> bool:
    """Whether ``p`` (3,) lies inside the shell at ``tau`` (0: the frame's start, 1: its end):
    the vertical ray up from ``p`` (nudged sideways) crosses an odd number of triangles, Eq. (T15).
    ``corners`` (3, 3) is scratch."""
    px = p[0] + obstacle.nudge[0]
    py = p[1] + obstacle.nudge[1]
    crossings = 0
    for f in range(obstacle.faces.shape[0]):
        for corner in range(3):
            _vertex(obstacle, obstacle.faces[f, corner], tau, corners[corner])
        ax, ay = corners[0, 0], corners[0, 1]
        # The triangle's (x, y) box first: most triangles are nowhere above the particle.
        if px < min(ax, corners[1, 0], corners[2, 0]) or px > max(ax, corners[1, 0], corners[2, 0]):
            continue
        if py < min(ay, corners[1, 1], corners[2, 1]) or py > max(ay, corners[1, 1], corners[2, 1]):
            continue
        v0x, v0y = corners[1, 0] - ax, corners[1, 1] - ay
        v1x, v1y = corners[2, 0] - ax, corners[2, 1] - ay
        det = v0x * v1y - v0y * v1x
        if abs(det) <= 1e-300:
            continue  # a vertical triangle: the ray runs along it
        qx, qy = px - ax, py - ay
        s = (qx * v1y - qy * v1x) / det
        t = (v0x * qy - v0y * qx) / det
        if s >= 0.0 and t >= 0.0 and s + t < 1.0:
            z = (
                corners[0, 2]
                + s * (corners[1, 2] - corners[0, 2])
                + t * (corners[2, 2] - corners[0, 2])
            )
            if z > p[2]:
                crossings += 1
    return crossings % 2 == 1


@njit(cache=True)
def _inside_box(p: np.ndarray, obstacle: Obstacle) -> bool:
    for k in range(3):
        if p[k] < obstacle.lower[k] or p[k] > obstacle.upper[k]:
            return False
    return True


@njit(cache=True)
def _first_crossing(
    a: np.ndarray,
    b: np.ndarray,
    obstacle: Obstacle,
    tau: float,
    corners: np.ndarray,
    normal: np.ndarray,
) -> float:
    """The least t in [0, 1] at which the segment a + t (b - a) meets a triangle of the shell at
    ``tau`` (Moller & Trumbore, J. Graphics Tools 2, 1997); 2 if it meets none. ``normal`` (3,)
    receives that triangle's unit normal, turned towards ``a`` (the side the segment came from)."""
    best = 2.0
    dx, dy, dz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    for f in range(obstacle.faces.shape[0]):
        for corner in range(3):
            _vertex(obstacle, obstacle.faces[f, corner], tau, corners[corner])
        e1x = corners[1, 0] - corners[0, 0]
        e1y = corners[1, 1] - corners[0, 1]
        e1z = corners[1, 2] - corners[0, 2]
        e2x = corners[2, 0] - corners[0, 0]
        e2y = corners[2, 1] - corners[0, 1]
        e2z = corners[2, 2] - corners[0, 2]
        px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
        det = e1x * px + e1y * py + e1z * pz
        if abs(det) <= 1e-300:
            continue  # the segment runs parallel to the triangle
        inverse = 1.0 / det
        tx, ty, tz = a[0] - corners[0, 0], a[1] - corners[0, 1], a[2] - corners[0, 2]
        u = (tx * px + ty * py + tz * pz) * inverse
        if u < 0.0 or u > 1.0:
            continue
        qx, qy, qz = ty * e1z - tz * e1y, tz * e1x - tx * e1z, tx * e1y - ty * e1x
        v = (dx * qx + dy * qy + dz * qz) * inverse
        if v < 0.0 or u + v > 1.0:
            continue
        t = (e2x * qx + e2y * qy + e2z * qz) * inverse
        if 0.0 <= t < best:
            best = t
            # e1 x e2, turned against the segment's direction (it points back to a).
            nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
            norm = math.sqrt(nx * nx + ny * ny + nz * nz)
            if nx * dx + ny * dy + nz * dz > 0.0:
                norm = -norm
            normal[0], normal[1], normal[2] = nx / norm, ny / norm, nz / norm
    return best


@njit(cache=True)
def push_out(
    x: np.ndarray,
    old: np.ndarray,
    first: int,
    obstacle: Obstacle,
    tau: float,
    pinned: np.ndarray,
    scratch: np.ndarray,
    gap: float = 0.0,
    normals: np.ndarray | None = None,
    reach: float = 0.0,
) -> int:
    """Put every particle ``first``.. of chain ``x`` (P, 3) that lies inside the shell at ``tau``
    back on its surface, the obstacle's clearance plus ``gap`` (m) outside (Eq. T16): where it was
    outside at the step's start ``old`` (P, 3), at the point where its path from there first meets
    the surface; where the wall came over it, at the nearest point of the surface. With a
    prescribed root (``first`` = 1) and ``reach`` (m, the chain's spacing) given, particle i is put
    where the straight line from the root to it first meets the surface instead wherever the
    wall's tangent plane at either point lies more than ``ROOT_REACH`` of i ``reach`` from the
    root (Eq. T16b): no point of that plane is within the chain's length from the root to it,
    so the chain could not hold it there. Marks the particles moved in ``pinned`` (P,) and
    returns their number; ``normals`` (P, 3), if given, receives each moved particle's unit
    outward normal of the surface where it was put (the triangle's its path or the line from
    the root crossed, or the direction from the particle to its nearest point), the wall's
    tangent plane there being what :func:`jellysim.tentacle.kernels.project_on_walls` keeps it
    outside of. ``scratch`` (11, 3) is work space."""
    if obstacle.faces.shape[0] == 0:
        return 0
    corners = scratch[0:3]
    work = scratch[3:8]
    nearest = scratch[8]
    best = scratch[9]  # where the particle is put
    crossed = scratch[10]  # the surface's outward unit normal there
    moved = 0
    for i in range(first, x.shape[0]):
        p = x[i]
        if not _inside_box(p, obstacle) or not inside_shell(p, obstacle, tau, corners):
            continue
        a = old[i]
        placed = False
        if not (_inside_box(a, obstacle) and inside_shell(a, obstacle, tau, corners)):
            # It moved in this step: stop it where its path meets the surface.
            placed = _stop_on_segment(a, p, obstacle, tau, gap, corners, best, crossed)
        if not placed:
            # The wall came over it: the nearest point of the surface.
            best_d2 = math.inf
            for f in range(obstacle.faces.shape[0]):
                for corner in range(3):
                    _vertex(obstacle, obstacle.faces[f, corner], tau, corners[corner])
                d2 = _closest_on_triangle(p, corners, work, nearest)
                if d2 < best_d2:
                    best_d2 = d2
                    best[:] = nearest
            distance = math.sqrt(best_d2)
            if not distance > 0.0:
                continue
            scale = 1.0 + (obstacle.clearance + gap) / distance
            for k in range(3):
                crossed[k] = (best[k] - p[k]) / distance
                best[k] = p[k] + scale * (best[k] - p[k])
        if first == 1 and reach > 0.0:
            # Eq. T16b: a plane beyond the prescribed root's reach, i segments, cannot hold it.
            height = 0.0
            for k in range(3):
                height += crossed[k] * (x[0, k] - best[k])
            if abs(height) > ROOT_REACH * i * reach and not (
                _inside_box(x[0], obstacle) and inside_shell(x[0], obstacle, tau, corners)
            ):
                _stop_on_segment(x[0], p, obstacle, tau, gap, corners, best, crossed)
        for k in range(3):
            x[i, k] = best[k]
            if normals is not None:
                normals[i, k] = crossed[k]
        pinned[i] = True
        moved += 1
    return moved


@njit(cache=True)
def _stop_on_segment(
    a: np.ndarray,
    b: np.ndarray,
    obstacle: Obstacle,
    tau: float,
    gap: float,
    corners: np.ndarray,
    out: np.ndarray,
    normal: np.ndarray,
) -> bool:
    """Where the segment from ``a`` (outside) to ``b`` (inside) first meets the shell at ``tau``,
    the obstacle's clearance plus ``gap`` back towards ``a``, into ``out`` (3,), with the crossed
    triangle's unit normal turned towards ``a`` into ``normal`` (3,); False (both untouched) if it
    meets none."""
    t = _first_crossing(a, b, obstacle, tau, corners, out)
    length = math.sqrt((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2 + (b[2] - a[2]) ** 2)
    if t > 1.0 or not length > 0.0:
        return False
    back = max(t - (obstacle.clearance + gap) / length, 0.0)
    for k in range(3):
        normal[k] = out[k]
        out[k] = a[k] + back * (b[k] - a[k])
    return True
