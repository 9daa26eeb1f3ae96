"""The soft bell's rendering surface (docs/theory/soft-bell.md §6, Eq. B12).

A closed shell mesh at rest (outer and inner half-ellipsoids, the topology of the kinematic bell's
:func:`jellysim.bell.kinematic.bell_faces`), each vertex moved by the weighted mean displacement
of the bell particles within ``SKIN_RADIUS x l0``: a smooth surface that follows the particles.
It is drawn, never simulated.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from jellysim import fields
from jellysim.bell.kinematic import MESH_RINGS, bell_faces
from jellysim.bell.soft import BellShape
from jellysim.fields import Dataset

SKIN_RADIUS = 2.5  # l0: particles that move a surface vertex


class BellSkin:
    """The surface over ``sectors`` meridians of a bell of ``shape`` whose particles rest at
    ``rest`` (B, 3) m, on the lattice of spacing ``l0`` (m)."""

    def __init__(self, shape: BellShape, rest: np.ndarray, sectors: int, l0: float) -> None:
        self.shape = shape
        self.rest = rest
        self.sectors = sectors
        self.angles = 2.0 * np.pi * np.arange(sectors) / sectors
        self.faces = bell_faces(sectors)
        self.rest_surface = self._rest_surface()
        self._weights = self._skin_weights(SKIN_RADIUS * l0)

    def _rest_surface(self) -> np.ndarray:
        """Closed shell mesh at rest (topology :func:`bell_faces`): apex, the outer ellipsoid's
        rings down to the margin, the inner one's back up, the inner apex."""
        shape = self.shape
        s = np.arange(1, MESH_RINGS + 1) / MESH_RINGS
        ring_s = np.concatenate([s, s[-2::-1]])
        outer = np.arange(len(ring_s)) < MESH_RINGS
        a = 0.5 * np.pi * ring_s
        r = np.where(outer, shape.radius, shape.radius - shape.wall)
        h = np.where(outer, shape.height, shape.height - shape.wall)
        rho = (r * np.sin(a))[:, None] * np.ones(self.sectors)
        z = (h * np.cos(a))[:, None] * np.ones(self.sectors)
        rings = np.stack(
            [rho * np.cos(self.angles), rho * np.sin(self.angles), z], axis=-1
        ).reshape(-1, 3)
        vertices = np.concatenate(
            [[[0.0, 0.0, shape.height]], rings, [[0.0, 0.0, shape.height - shape.wall]]]
        )
        return vertices + shape.centre

    def rim(self) -> np.ndarray:
        """The outer edge of the drawn margin at rest, one vertex per meridian (sectors, 3) m:
        the outer ellipsoid's lowest ring."""
        first = 1 + (MESH_RINGS - 1) * self.sectors
        return self.rest_surface[first : first + self.sectors]

    def underside_centre(self) -> tuple[sparse.csr_matrix, np.ndarray]:
        """The drawn underside's centre, the inner ellipsoid's apex (the mesh's last vertex):
        its (1, B) weights over the particles' displacements from rest and its rest point (3,)
        m. It moves as :meth:`surface` moves that vertex."""
        return self._weights[-1:], self.rest_surface[-1].copy()

    def _skin_weights(self, reach: float) -> sparse.csr_matrix:
        """(V, B) weights, rows summing to 1, of the particles within ``reach`` (m) of each rest
        vertex, ``(1 - d / r)^2`` (Eq. B12); the nearest particle if none is that close."""
        from scipy.spatial import cKDTree

        tree = cKDTree(self.rest)
        rows, cols, values = [], [], []
        for v, near in enumerate(tree.query_ball_point(self.rest_surface, reach)):
            if not near:
                near = [int(tree.query(self.rest_surface[v])[1])]
            d = np.linalg.norm(self.rest[near] - self.rest_surface[v], axis=1)
            w = (1.0 - d / reach) ** 2 + 1e-12
            rows += [v] * len(near)
            cols += list(near)
            values += list(w / w.sum())
        return sparse.csr_matrix(
            (values, (rows, cols)), shape=(len(self.rest_surface), len(self.rest))
        )

    def surface(self, positions: np.ndarray) -> np.ndarray:
        """The rendering surface (V, 3) m over the bell particles at ``positions`` (B, 3)."""
        return self.rest_surface + self._weights @ (positions - self.rest)

    def dataset(self) -> Dataset:
        return fields.BELL_SURFACE_VERTICES.dataset(V=len(self.rest_surface))

    def static_datasets(self) -> dict[str, tuple[np.ndarray, str]]:
        return {fields.BELL_SURFACE_FACES.path: (self.faces, fields.BELL_SURFACE_FACES.units)}
