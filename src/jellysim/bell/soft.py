"""``bell.model = "mass-spring"``: the soft Moon Jelly bell's body (paper §4.2.1,
docs/theory/soft-bell.md §1-3): its shape, its particles, its springs and its circular muscle.

- Shape (Eq. B7, :class:`BellShape`): in the bell frame (axis +z through the tank's centre, margin
  plane at ``bell.margin_height`` above the floor), the shell between two half-ellipsoids of
  revolution, outer semi-axes (R, H) and inner (R - w, H - w) with ``w = thickness x H``: the
  lattice cells whose centres satisfy ``rho^2/R^2 + h^2/H^2 < 1 <= rho^2/(R-w)^2 + h^2/(H-w)^2``
  with h >= 0. The particles are carved out of the fluid's lattice (the coupling builds it once),
  so the number density is right at t = 0.
- Springs (Eq. B8 = paper Eq. 6): every pair closer than ``spring_radius x l0`` at the start, rest
  length the initial distance, stiffness ``spring_stiffness``.
- Circular muscle (Eq. B9): the springs of the margin band (both ends less than ``muscle_band x
  H`` above the margin plane) that run around the ring (the spring's direction within 45 degrees
  of the circumferential direction at its midpoint). With the activation ``a(t)`` in [0, 1], the
  pulse waveform of the kinematic bell (``bell.waveform``, ``jet_fraction``, ``period``), their rest
  length is ``L0 (1 - muscle_ratio a)`` and their stiffness ``k (1 + (muscle_stiffening - 1) a)``:
  the paper's "ratio 0.40" and "x 50" (DESIGN §2 reading of the ratio). With ``muscle_taper`` t > 0
  a muscle spring whose mid-point is h above the margin plane has its shortening and stiffening
  scaled by ``w = 1 - t h / (muscle_band x H)``: the band bends the bell gradually instead of
  folding it at the band's top (docs/theory/soft-bell.md §3).

The bell in the water (§4), the margin that drives the roots (§5) and the rendering skin (§6)
live in :mod:`jellysim.coupling.bell_in_fluid`, :mod:`jellysim.coupling.margin` and
:mod:`jellysim.bell.skin`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from jellysim import fields
from jellysim.bell import springs as kernels
from jellysim.bell.kinematic import contraction_waveform, waveform_peaks
from jellysim.config.schema import Scene
from jellysim.errors import SimulationUnstable
from jellysim.tentacle.roots import NO_FORCING, Forcing

CIRCUMFERENTIAL = math.cos(math.radians(45.0))  # muscle springs: |e . e_theta| at least this
IMPLICIT_TOLERANCE = 1e-10  # relative residual of the implicit springs' CG
SPRING_SAFETY = 0.4  # of the explicit stability limit 2 / omega_max


class Springs(NamedTuple):
    """The spring network, built once: ``pairs`` (S, 2) int64 particle indices, ``rest_length``
    (S,) m, ``muscle`` (S,) bool, and the adjacency (``start`` (B+1,), ``edges`` and ``signs``
    (2S,)) through which each particle gathers its springs."""

    pairs: np.ndarray
    rest_length: np.ndarray
    muscle: np.ndarray
    start: np.ndarray
    edges: np.ndarray
    signs: np.ndarray


def build_springs(
    positions: np.ndarray, radius: float, muscle: Callable[[np.ndarray], np.ndarray]
) -> Springs:
    """Springs between every pair closer than ``radius`` (m) at ``positions`` (B, 3), sorted;
    ``muscle`` maps the pairs (S, 2) to the (S,) mask of muscle springs."""
    from scipy.spatial import cKDTree

    pairs = np.asarray(sorted(cKDTree(positions).query_pairs(radius)), dtype=np.int64)
    pairs = pairs.reshape(-1, 2)
    rest = np.linalg.norm(positions[pairs[:, 1]] - positions[pairs[:, 0]], axis=1)
    n = positions.shape[0]
    ends = np.concatenate([pairs[:, 0], pairs[:, 1]])
    edges = np.concatenate([np.arange(len(pairs)), np.arange(len(pairs))])
    signs = np.concatenate([np.ones(len(pairs)), -np.ones(len(pairs))])
    order = np.lexsort((edges, ends))
    start = np.zeros(n + 1, dtype=np.int64)
    np.add.at(start, ends + 1, 1)
    return Springs(
        pairs,
        rest,
        muscle(pairs),
        np.cumsum(start),
        edges[order].astype(np.int64),
        signs[order],
    )


def explicit_spring_dt(stiffness_sum: float, mass: float) -> float:
    """The explicit stage's limit for springs (s) on particles of ``mass`` (kg) whose spring
    constants sum to at most ``stiffness_sum`` (N/m) at a particle: ``SPRING_SAFETY x 2 /
    omega``, ``omega^2 = 4 stiffness_sum / m``, twice the block Gershgorin bound on the stiffness
    matrix's largest eigenvalue (each spring's 3 x 3 block ``k e e^T`` has norm k, so
    ``omega_max^2 <= max_i 2 sum_e k_e / m`` whatever the springs' directions):
    docs/theory/soft-bell.md §4."""
    omega = math.sqrt(4.0 * stiffness_sum / mass)
    return SPRING_SAFETY * 2.0 / omega if omega > 0 else math.inf


def margin_forcing(scene: Scene) -> Forcing:
    """The scales of a margin that loses ``bell.muscle_ratio`` of its radius each pulse (the
    soft bell's root driver's forcing, known from the scene alone)."""
    b = scene.bell
    if b.muscle_ratio == 0.0:
        return NO_FORCING
    slope, curvature, period = waveform_peaks(b.waveform, b.jet_fraction)
    swing = b.radius * b.muscle_ratio
    return Forcing(swing * slope / b.period, swing * curvature / b.period**2, period * b.period)


class BellShape:
    """The bell's rest shape (Eq. B7): ``centre`` (3,) m of the margin plane on the axis,
    ``radius`` R and ``height`` H (m), ``wall`` w (m)."""

    def __init__(self, scene: Scene) -> None:
        b, f = scene.bell, scene.fluid
        self.radius, self.height = b.radius, b.height
        self.wall = b.thickness * b.height
        self.centre = np.array([0.5 * f.tank_width, 0.5 * f.tank_depth, b.margin_height])

    def cylindrical(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Distance from the axis (m), height above the margin plane (m) and azimuth (rad) of
        each point (N, 3), each (N,)."""
        relative = points - self.centre
        return (
            np.hypot(relative[:, 0], relative[:, 1]),
            relative[:, 2],
            np.arctan2(relative[:, 1], relative[:, 0]),
        )

    def shell(self, points: np.ndarray) -> np.ndarray:
        """Whether each lattice point (N, 3) lies in the bell's shell at rest (Eq. B7)."""
        rho, h, _ = self.cylindrical(points)
        outer = (rho / self.radius) ** 2 + (h / self.height) ** 2 < 1.0
        inner = (rho / (self.radius - self.wall)) ** 2 + (h / (self.height - self.wall)) ** 2
        return (h >= 0.0) & outer & (inner >= 1.0)


class SoftBell:
    """The mass-spring body: ``rest`` (B, 3) m, the lattice cells carved for it; its springs and
    circular muscle (Eq. B8-B9); ``mass`` (kg) of each particle, the water's in a cell of l0^3."""

    def __init__(self, scene: Scene, shape: BellShape, rest: np.ndarray) -> None:
        b = scene.bell
        l0 = scene.fluid.spacing
        self.shape = shape
        self.rest = rest
        self.period, self.waveform, self.jet_fraction = b.period, b.waveform, b.jet_fraction
        self.stiffness = b.spring_stiffness
        self.muscle_ratio, self.muscle_stiffening = b.muscle_ratio, b.muscle_stiffening
        self.mass = scene.water.density * l0**3
        self.integration = b.spring_integration
        self._forcing = margin_forcing(scene)

        _, height, _ = shape.cylindrical(rest)
        band = height < b.muscle_band * b.height

        def muscle(pairs: np.ndarray) -> np.ndarray:
            ends = rest[pairs]
            direction = ends[:, 1] - ends[:, 0]
            direction /= np.linalg.norm(direction, axis=1)[:, None]
            mid = ends.mean(axis=1) - shape.centre
            theta = np.stack([-mid[:, 1], mid[:, 0], np.zeros(len(mid))], axis=1)
            theta /= np.maximum(np.linalg.norm(theta, axis=1), 1e-300)[:, None]
            along = np.abs(np.einsum("ij,ij->i", direction, theta))
            return band[pairs[:, 0]] & band[pairs[:, 1]] & (along >= CIRCUMFERENTIAL)

        self.springs = build_springs(rest, b.spring_radius * l0, muscle)
        # Each muscle spring's share of the contraction (Eq. B9; 1 everywhere with no taper).
        self._muscle_weight: np.ndarray | None = None
        if b.muscle_taper > 0.0:
            mid = height[self.springs.pairs].mean(axis=1)[self.springs.muscle]
            share = 1.0 - b.muscle_taper * mid / (b.muscle_band * b.height)
            self._muscle_weight = np.clip(share, 0.0, 1.0)
        self._tensions = np.zeros((len(self.springs.pairs), 3))
        self._stiffness = np.full(len(self.springs.pairs), self.stiffness)
        self._rest_length = self.springs.rest_length.copy()
        # Per particle: the stiffness of its passive springs and of its muscle springs at rest.
        muscle_share = self.springs.muscle.astype(np.float64)
        self._passive_total = np.zeros(len(rest))
        self._muscle_total = np.zeros(len(rest))
        for column in (0, 1):
            ends = self.springs.pairs[:, column]
            np.add.at(self._passive_total, ends, self.stiffness * (1.0 - muscle_share))
            np.add.at(self._muscle_total, ends, self.stiffness * muscle_share)

    @property
    def muscle_weight(self) -> np.ndarray | None:
        """Each muscle spring's share of the contraction (Eq. B9, ``muscle_taper``), in the
        order of the muscle springs; None where every share is 1."""
        return self._muscle_weight

    def activation(self, time: float) -> float:
        """Muscle activation a(t) in [0, 1]: 0 relaxed, 1 fully contracted (Eq. B9)."""
        c, _ = contraction_waveform(
            np.array([math.fmod(time / self.period, 1.0)]), self.waveform, self.jet_fraction
        )
        return float(c[0])

    def spring_forces(self, positions: np.ndarray, time: float, out: np.ndarray) -> None:
        """Spring forces (B, 3) N on the bell particles at ``positions`` and ``time`` into
        ``out`` (Eq. B8-B9)."""
        a = self.activation(time)
        muscle = self.springs.muscle
        weight = 1.0 if self._muscle_weight is None else self._muscle_weight
        self._rest_length[:] = self.springs.rest_length
        self._rest_length[muscle] *= 1.0 - self.muscle_ratio * a * weight
        self._stiffness[:] = self.stiffness
        self._stiffness[muscle] *= 1.0 + (self.muscle_stiffening - 1.0) * a * weight
        kernels.spring_tensions(
            positions, self.springs.pairs, self._rest_length, self._stiffness, self._tensions
        )
        s = self.springs
        kernels.gather_forces(self._tensions, s.start, s.edges, s.signs, out)

    def implicit_force(
        self,
        positions: np.ndarray,
        velocities: np.ndarray,
        time: float,
        dt: float,
        out: np.ndarray,
    ) -> int:
        """The springs' force (B, 3) N over a step ``dt`` (s) from ``time`` by linearised
        backward Euler [Baraff & Witkin 1998], into ``out``: ``m dv / dt`` with dv solving
        ``(m I - dt^2 K) dv = dt (F + dt K v)``, F and K = dF/dr at ``positions`` with the muscle
        at ``time + dt``. Fed to the explicit stage in place of F, it gives the bell particles
        the backward-Euler velocity change, stable for any dt (docs/theory/soft-bell.md §4).
        Returns the CG iterations."""
        self.spring_forces(positions, time + dt, out)
        s = self.springs
        change = np.empty_like(out)
        iterations, residual = kernels.implicit_velocity_change(
            positions, velocities, s.pairs, self._rest_length, self._stiffness,
            s.start, s.edges, s.signs, out, self.mass, dt, IMPLICIT_TOLERANCE, 1000, change,
        )  # fmt: skip
        if not residual <= IMPLICIT_TOLERANCE:
            raise SimulationUnstable(
                f"the implicit spring solve stopped at relative residual {residual:.3g} after "
                f"{iterations} iterations at t = {time:.6g} s",
                time=time,
            )
        out[:] = self.mass * change / dt
        return int(iterations)

    def step_force(
        self,
        positions: np.ndarray,
        velocities: np.ndarray,
        time: float,
        dt: float,
        out: np.ndarray,
    ) -> None:
        """The springs' force (B, 3) N for an MPS step of ``dt`` (s) from ``time``, into ``out``:
        :meth:`spring_forces` now (``spring_integration = "explicit"``) or
        :meth:`implicit_force`."""
        if self.integration == "explicit":
            self.spring_forces(positions, time, out)
        else:
            self.implicit_force(positions, velocities, time, dt, out)

    def stable_dt(self, activation: float = 1.0) -> float:
        """The explicit stage's limit for the springs (s) with the muscle at ``activation`` (the
        run uses full stiffening throughout): :func:`explicit_spring_dt` of the largest sum of
        spring constants at a particle, the muscle's stiffened (with ``muscle_taper``, a bound:
        every muscle spring taken at its full share)."""
        factor = 1.0 + max(self.muscle_stiffening - 1.0, 0.0) * activation
        total = self._passive_total + factor * self._muscle_total
        return explicit_spring_dt(float(total.max(initial=0.0)), self.mass)

    def forcing(self) -> Forcing:
        """The scales of a margin that loses ``muscle_ratio`` of its radius each pulse."""
        return self._forcing

    def static_datasets(self) -> dict[str, tuple[np.ndarray, str]]:
        """The body's topology and rest state, written once."""
        return {
            fields.BELL_SPRINGS.path: (self.springs.pairs, fields.BELL_SPRINGS.units),
            fields.BELL_MUSCLE.path: (self.springs.muscle, fields.BELL_MUSCLE.units),
            fields.BELL_REST_POSITION.path: (self.rest, fields.BELL_REST_POSITION.units),
        }
