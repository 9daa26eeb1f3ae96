"""The parity test of a point against a closed triangle surface, as the checks on stored results
use it (tests/integration/test_nothing_through_the_bell.py, tests/unit/test_tentacle_contact.py)."""

from __future__ import annotations

import numpy as np

EDGE_NUDGE = np.array([1.37e-9, 2.71e-9, 0.0])  # of the surface's size: off every mesh edge


def inside_closed_surface(
    points: np.ndarray, vertices: np.ndarray, faces: np.ndarray
) -> np.ndarray:
    """Whether each point (N, 3) lies inside the closed triangle surface: the number of
    triangles that a ray from the point along +z crosses is odd.

    The points are nudged sideways by a few 1e-9 of the surface's size before the count, so that
    no ray runs exactly along an edge of the mesh (a root's chain hanging straight down at the
    angle of a mesh meridian would otherwise cross the edge's two triangles twice or not at all,
    and be miscounted)."""
    inside = np.zeros(len(points), dtype=bool)
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    near = np.all((points >= low) & (points <= high), axis=1)
    if not near.any():
        return inside
    p = points[near] + EDGE_NUDGE * float(np.max(high - low))
    a, b, c = (vertices[faces[:, k]] for k in range(3))  # (M, 3) each, the triangles' corners
    # Barycentric coordinates of each point's (x, y) in each triangle's (x, y) projection.
    v0, v1 = (b - a)[:, :2], (c - a)[:, :2]
    det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]  # (M,)
    usable = np.abs(det) > 1e-18
    a, v0, v1, det = a[usable], v0[usable], v1[usable], det[usable]
    ab_z, ac_z = (b[usable] - a)[:, 2], (c[usable] - a)[:, 2]
    crossings = np.zeros(len(p), dtype=np.int64)
    for start in range(0, len(p), 256):
        q = p[start : start + 256, None, :2] - a[None, :, :2]  # (n, M, 2)
        s = (q[..., 0] * v1[None, :, 1] - q[..., 1] * v1[None, :, 0]) / det
        t = (v0[None, :, 0] * q[..., 1] - v0[None, :, 1] * q[..., 0]) / det
        hit = (s >= 0.0) & (t >= 0.0) & (s + t < 1.0)
        z = a[None, :, 2] + s * ab_z[None] + t * ac_z[None]
        crossings[start : start + 256] = np.sum(hit & (z > p[start : start + 256, None, 2]), axis=1)
    inside[np.flatnonzero(near)] = crossings % 2 == 1
    return inside


def distance_to_surface(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The distance (N,) from each point (N, 3) to the nearest point of the triangle surface:
    the nearest of its distance to each triangle's plane where its foot falls inside the
    triangle, and to each edge segment. Vectorised over the triangles, a point at a time."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    edges = [(a, b), (b, c), (c, a)]
    result = np.empty(len(points))
    for n, p in enumerate(points):
        height = np.sum((p - a) * normal, axis=1)
        foot = p - height[:, None] * normal
        # The foot is inside when it lies on the inner side of all three edges.
        inside = np.ones(len(a), dtype=bool)
        for start, end in edges:
            inside &= np.sum(np.cross(end - start, foot - start) * normal, axis=1) >= 0.0
        best = np.min(np.abs(height[inside]), initial=np.inf)
        for start, end in edges:
            e = end - start
            s = np.clip(np.sum((p - start) * e, axis=1) / np.sum(e * e, axis=1), 0.0, 1.0)
            best = min(best, float(np.min(np.linalg.norm(start + s[:, None] * e - p, axis=1))))
        result[n] = best
    return result
