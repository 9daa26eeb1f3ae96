"""Probes of a fluid-only scene: the water's depth along vertical lines and the pressure on the
walls at points (SPHERIC benchmark Test 2's gauges H1-H4 and sensors P1-P8).

Height (docs/theory/fluid.md Eq. F14): the depth of water along the vertical line at the
horizontal place ``c`` is the integral of the liquid fraction along it, which the particles give
as ``h(c) = sum_j V0 W(|x_j - c|)`` over the live fluid particles, with ``x_j`` their horizontal
coordinates, ``V0`` the volume (area in 2-D) each lattice site stands for and ``W`` the
normalised kernel ``W(r) = 3 / (pi R^2) (1 - r^2/R^2)^2`` in the horizontal plane (3-D) or
``15 / (16 R) (1 - x^2/R^2)^2`` along the horizontal line (2-D), ``R = 2 l0``, zero beyond R.
Still water of depth H reads H (its layers tile the kernel); a lone splash particle adds at most
``V0 W(0)``, 0.17 l0 in 3-D on the fcc lattice.

Pressure (Eq. F15): the wall pressure at a point ``c`` on a face is the weighted mean of the
pressures of the wall particles of that face within ``R = 2 l0``, ``p(c) = sum_j w_j p_j /
sum_j w_j`` with ``w_j = (1 - r_j / R)^2``; the wall particles carry the pressure of the Poisson
equation (dummies do not). A wall particle belongs to the face whose plane is nearest to it
among the tank's walls and the faces of the obstacle it is in (:func:`face_of`), so that a
sensor near an edge (the box's P4 and P5, 0.021 m from its top edge) does not read the other
face's walls. The walls do not move, so the weights are computed once. The result stores
its mean over each frame's steps, weighted by their dt: single steps' pressures are noisy.

The sums of Eq. (F15) are taken where the pressure is: the solver's ``pressure_gauge(rows,
weights)`` gives a function that returns them for the pressure now, :func:`weighted_sums` on
the host (:class:`~jellysim.fluid.mps.MPSSolver`), a kernel on the GPU
(:class:`~jellysim.fluid.gpu.GPUSolver`, which downloads K numbers a step, not the N
pressures).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from jellysim.fluid.geometry import FLUID, SITE_VOLUME, WALL

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

PROBE_RADIUS = 2.0  # R of both probes, in l0


class HeightProbes:
    """Water depth (m) along vertical lines at ``places`` ((H, D - 1) m, the horizontal
    coordinates), Eq. (F14)."""

    def __init__(self, places: np.ndarray, l0: float, dim: int, lattice: str) -> None:
        self.places = np.asarray(places, dtype=np.float64).reshape(-1, dim - 1)
        self.radius = PROBE_RADIUS * l0
        self.site_volume = SITE_VOLUME[lattice] * l0**dim
        self.dim = dim

    def measure(self, position: np.ndarray, kind: np.ndarray, alive: np.ndarray) -> np.ndarray:
        """(H,) m: the depths for particle ``position`` (N, D) m, ``kind`` (N,), ``alive`` (N,)."""
        water = position[alive & (kind == FLUID), :-1]
        depths = np.zeros(len(self.places))
        r2 = self.radius**2
        if self.dim == 3:
            norm = 3.0 / (np.pi * r2)
        else:
            norm = 15.0 / (16.0 * self.radius)
        for k, place in enumerate(self.places):
            s2 = ((water - place) ** 2).sum(axis=1) / r2
            near = s2 < 1.0
            depths[k] = self.site_volume * norm * ((1.0 - s2[near]) ** 2).sum()
        return depths


def face_of(points: np.ndarray, tank: np.ndarray, boxes: np.ndarray, margin: float) -> np.ndarray:
    """(M,) int: the solid face each of ``points`` (M, D) m lies on or behind: the face of the
    tank's walls (0 .. 2D - 2: the planes x = 0, y = 0, (z = 0,) then x = W, (y = depth)) or of
    an obstacle box ``b`` (``2D - 1 + 2D b + f``, f as the tank's, with the top face) whose plane
    is nearest, an obstacle's faces taking the points within ``margin`` (m) of its box, the
    tank's the others (a wall particle belongs to the solid it was built in). ``tank``: the
    tank's inner upper corner (D,) m; ``boxes``: (B, 2D) m, lower then upper corners."""
    points = np.asarray(points, dtype=np.float64)
    dim = points.shape[1]
    # distances to the tank's planes: the lower ones, then the upper ones but the open top
    planes = [np.abs(points[:, k]) for k in range(dim)]
    planes += [np.abs(points[:, k] - tank[k]) for k in range(dim - 1)]
    distance = np.column_stack(planes)
    for box in np.asarray(boxes, dtype=np.float64).reshape(-1, 2 * dim):
        lower, upper = box[:dim], box[dim:]
        near = np.all((points > lower - margin) & (points < upper + margin), axis=1)
        distance[near] = np.inf
        faces = np.column_stack(
            [np.abs(points[:, k] - lower[k]) for k in range(dim)]
            + [np.abs(points[:, k] - upper[k]) for k in range(dim)]
        )
        # a face on the tank's wall or floor has no wall layer of its own (geometry.box_obstacle)
        on_tank = np.concatenate([lower <= 0.0, upper[: dim - 1] >= tank[: dim - 1], [False]])
        faces[:, on_tank] = np.inf
        distance = np.column_stack([distance, np.where(near[:, None], faces, np.inf)])
    return np.argmin(distance, axis=1)


def weighted_sums(
    values: np.ndarray, rows: Sequence[np.ndarray], weights: Sequence[np.ndarray]
) -> np.ndarray:
    """(K,): ``sum_j weights[k][j] values[rows[k][j]]`` for each k, of ``values`` (N,) and K
    pairs of ``rows`` (int) and ``weights`` (float, of the same length): Eq. (F15) on the host,
    with the weights normalised."""
    return np.array([w @ values[r] for r, w in zip(rows, weights, strict=True)])


class PressureProbes:
    """Wall pressure (Pa) at ``points`` ((K, D) m), Eq. (F15), averaged over the steps of a
    frame by :meth:`add_step` and :meth:`frame_mean`. ``tank`` and ``boxes``: as
    :func:`face_of`. ``rows[k]`` (int) and ``weights[k]`` (summing to 1) are probe k's wall
    particles and their weights ``w_j / sum_j w_j``."""

    def __init__(
        self,
        points: np.ndarray,
        position: np.ndarray,
        kind: np.ndarray,
        l0: float,
        tank: np.ndarray,
        boxes: np.ndarray,
    ) -> None:
        self.points = np.asarray(points, dtype=np.float64).reshape(-1, position.shape[1])
        radius = PROBE_RADIUS * l0
        walls = np.flatnonzero(kind == WALL)
        wall_faces = face_of(position[walls], tank, boxes, 1e-6 * l0)
        probe_faces = face_of(self.points, tank, boxes, 0.5 * l0)  # as the scene checks
        self.rows: list[np.ndarray] = []
        self.weights: list[np.ndarray] = []
        for point, face in zip(self.points, probe_faces, strict=True):
            r = np.sqrt(((position[walls] - point) ** 2).sum(axis=1))
            near = (r < radius) & (wall_faces == face)
            if not near.any():
                raise ValueError(f"no wall particle within {radius:g} m of the probe at {point}")
            w = (1.0 - r[near] / radius) ** 2
            self.rows.append(walls[near])
            self.weights.append(w / w.sum())
        self._sum = np.zeros(len(self.points))
        self._time = 0.0

    def measure(self, pressure: np.ndarray) -> np.ndarray:
        """(K,) Pa: the probes' pressures for the particles' ``pressure`` (N,) Pa now."""
        return weighted_sums(pressure, self.rows, self.weights)

    def add_step(self, probe_pressure: np.ndarray, dt: float) -> None:
        """Add a step of ``dt`` (s) that ended with the probes' pressures ``probe_pressure``
        (K,) Pa (:meth:`measure`, or the solver's ``pressure_gauge``) to the frame's mean."""
        self._sum += dt * probe_pressure
        self._time += dt

    def frame_mean(self, now: Callable[[], np.ndarray]) -> np.ndarray:
        """(K,) Pa: the mean over the steps added since the last call (``now()``, the probes'
        pressures now, when none was), and start the next frame's."""
        mean = self._sum / self._time if self._time > 0 else now()
        self._sum[:] = 0.0
        self._time = 0.0
        return mean
