"""``bell.model = "mass-spring"``: the soft Moon Jelly bell of the paper's Case 2 (§4.2.1-4.2.4).

The bell is a set of particles carved out of the MPS fluid lattice (docs/theory/soft-bell.md,
Eq. B7-B12):

- Shape (Eq. B7): in the bell frame (axis +z through the tank's centre, margin plane at
  ``bell.margin_height`` above the floor), the shell between two half-ellipsoids of revolution,
  outer semi-axes (R, H) and inner (R - w, H - w) with ``w = thickness x H``: the lattice cells
  whose centres satisfy ``rho^2/R^2 + h^2/H^2 < 1 <= rho^2/(R-w)^2 + h^2/(H-w)^2`` with h >= 0.
  The particles sit exactly where fluid particles would, so the number density is right at t = 0.
- Springs (Eq. B8 = paper Eq. 6): every pair closer than ``spring_radius x l0`` at the start, rest
  length the initial distance, stiffness ``spring_stiffness``.
- Circular muscle (Eq. B9): the springs of the margin band (both ends less than ``muscle_band x
  H`` above the margin plane) that run around the ring (the spring's direction within 45 degrees
  of the circumferential direction at its midpoint). With the activation ``a(t)`` in [0, 1], the
  pulse waveform of the kinematic bell (``bell.waveform``, ``jet_fraction``, ``period``), their rest
  length is ``L0 (1 - muscle_ratio a)`` and their stiffness ``k (1 + (muscle_stiffening - 1) a)``:
  the paper's "ratio 0.40" and "x 50" (DESIGN §2 reading of the ratio).
- Coupling (§4.2.2): bell particles are fluid particles of the MPS solver; the spring forces enter
  its explicit stage as a force density ``F / l0^3``. They feel gravity and buoyancy like water
  (neutral buoyancy).
- Roots (Eq. B10-B11): tentacle base points and the margin polyline are Gaussian-weighted means
  (over the arc, width ``MARGIN_SMOOTHING x l0``) of the lowest particle layer, recorded each frame
  with their velocities and driven between frames by cubic Hermite interpolation (C1 in time). The
  clamp direction, -z at rest, turns with the wall: with the mean of the third layer up, the
  meridian angle of (root - upper point) is tracked.
- Rendering surface (Eq. B12): a closed shell mesh at rest (outer and inner half-ellipsoids),
  each vertex moved by the weighted mean displacement of the bell particles within
  ``SKIN_RADIUS x l0``: a smooth surface that follows the particles.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from scipy import sparse

from jellysim.bell import Forcing, RootDriver, register
from jellysim.bell import springs as kernels
from jellysim.bell.kinematic import (
    MESH_RINGS,
    bell_faces,
    contraction_waveform,
    sector_count,
    waveform_peaks,
)
from jellysim.config.schema import Scene
from jellysim.errors import SimulationUnstable
from jellysim.fluid.geometry import water_block
from jellysim.io.result import Dataset

MARGIN_SMOOTHING = 1.5  # l0: standard deviation of the Gaussian along the margin arc
SKIN_RADIUS = 2.5  # l0: particles that move a surface vertex
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


class Record(NamedTuple):
    """What the bell drove the tentacles with at one frame: roots (T, 3) m and velocities m/s,
    clamp directions (T, 3), the margin polyline (R, 3) m, the bell's mean velocity (3,) m/s."""

    roots: np.ndarray
    velocities: np.ndarray
    directions: np.ndarray
    margin: np.ndarray
    bell_velocity: np.ndarray


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


class SoftBell(RootDriver):
    """The mass-spring bell: rest particles, springs, muscle, margin sampling and the per-frame
    records that drive the tentacle roots (:class:`jellysim.bell.RootDriver`)."""

    def __init__(self, scene: Scene) -> None:
        b, f = scene.bell, scene.fluid
        self.scene = scene
        self.l0 = l0 = f.spacing
        self.radius, self.height = b.radius, b.height
        self.wall = b.thickness * b.height
        self.centre = np.array([0.5 * f.tank_width, 0.5 * f.tank_depth, b.margin_height])
        self.period, self.waveform, self.jet_fraction = b.period, b.waveform, b.jet_fraction
        self.stiffness = b.spring_stiffness
        self.muscle_ratio, self.muscle_stiffening = b.muscle_ratio, b.muscle_stiffening
        self.mass = scene.water.density * l0**3
        self.integration = b.spring_integration
        self.frame_dt = 1.0 / scene.fps
        self.tentacles = scene.tentacles.count

        water = water_block(0.0, f.tank_width, 0.0, f.tank_depth, l0, 0.0, f.water_height)
        self.rest = water[self.shell(water)]
        rho, height, angle = self._cylindrical(self.rest)
        band = height < b.muscle_band * b.height

        def muscle(pairs: np.ndarray) -> np.ndarray:
            ends = self.rest[pairs]
            direction = ends[:, 1] - ends[:, 0]
            direction /= np.linalg.norm(direction, axis=1)[:, None]
            mid = ends.mean(axis=1) - self.centre
            theta = np.stack([-mid[:, 1], mid[:, 0], np.zeros(len(mid))], axis=1)
            theta /= np.maximum(np.linalg.norm(theta, axis=1), 1e-300)[:, None]
            along = np.abs(np.einsum("ij,ij->i", direction, theta))
            return band[pairs[:, 0]] & band[pairs[:, 1]] & (along >= CIRCUMFERENTIAL)

        self.springs = build_springs(self.rest, b.spring_radius * l0, muscle)
        self._tensions = np.zeros((len(self.springs.pairs), 3))
        self._stiffness = np.full(len(self.springs.pairs), self.stiffness)
        self._rest_length = self.springs.rest_length.copy()
        # Per particle: the stiffness of its passive springs and of its muscle springs at rest.
        muscle_share = self.springs.muscle.astype(np.float64)
        self._passive_total = np.zeros(len(self.rest))
        self._muscle_total = np.zeros(len(self.rest))
        for column in (0, 1):
            ends = self.springs.pairs[:, column]
            np.add.at(self._passive_total, ends, self.stiffness * (1.0 - muscle_share))
            np.add.at(self._muscle_total, ends, self.stiffness * muscle_share)

        # Margin sampling (Eq. B10): the lowest layer, and the third layer for the clamp angle.
        sectors = sector_count(max(self.tentacles, 1), 0)
        self.sectors = sectors
        self.sample_angles = 2.0 * np.pi * np.arange(sectors) / sectors
        self.root_every = sectors // self.tentacles if self.tentacles else 0
        self._margin_weights = self._ring_weights(rho, angle, height < l0)
        self._upper_weights = self._ring_weights(rho, angle, (height >= 2 * l0) & (height < 3 * l0))

        # Rendering surface (Eq. B12).
        self.faces = bell_faces(sectors)
        self.rest_surface = self._rest_surface()
        self._skin = self._skin_weights()

        self.position = self.rest.copy()
        self.velocity = np.zeros_like(self.rest)
        self._rest_meridian = self._meridian_angles(self.rest)
        self.records: dict[int, Record] = {}
        self.record(0, self.position, self.velocity)

    # Geometry (Eq. B7).

    def _cylindrical(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        relative = points - self.centre
        return (
            np.hypot(relative[:, 0], relative[:, 1]),
            relative[:, 2],
            np.arctan2(relative[:, 1], relative[:, 0]),
        )

    def shell(self, points: np.ndarray) -> np.ndarray:
        """Whether each lattice point (N, 3) lies in the bell's shell at rest (Eq. B7)."""
        rho, h, _ = self._cylindrical(points)
        outer = (rho / self.radius) ** 2 + (h / self.height) ** 2 < 1.0
        inner = (rho / (self.radius - self.wall)) ** 2 + (h / (self.height - self.wall)) ** 2
        return (h >= 0.0) & outer & (inner >= 1.0)

    def _ring_weights(
        self, rho: np.ndarray, angle: np.ndarray, layer: np.ndarray
    ) -> sparse.csr_matrix:
        """(R, B) weights, rows summing to 1: per sample angle, a Gaussian over the arc length to
        the particles of ``layer`` (Eq. B10)."""
        sigma = MARGIN_SMOOTHING * self.l0
        gap = np.angle(np.exp(1j * (angle[None, :] - self.sample_angles[:, None])))
        weights = np.exp(-0.5 * (gap * rho[None, :] / sigma) ** 2) * layer[None, :]
        weights[np.abs(gap * rho[None, :]) > 3.0 * sigma] = 0.0
        total = weights.sum(axis=1)
        if np.any(total <= 0.0):
            raise ValueError("the bell's margin layer has a gap: refine fluid.spacing")
        return sparse.csr_matrix(weights / total[:, None])

    def _meridian_angles(self, positions: np.ndarray) -> np.ndarray:
        """Per sample: the angle of (margin point - upper point) in its meridian plane (R,)."""
        margin = self._margin_weights @ positions
        upper = self._upper_weights @ positions
        axis_point = margin.mean(axis=0)
        radial = margin - axis_point
        radial[:, 2] = 0.0
        radial /= np.linalg.norm(radial, axis=1)[:, None]
        d = margin - upper
        return np.arctan2(np.einsum("ij,ij->i", d, radial), -d[:, 2])

    def _rest_surface(self) -> np.ndarray:
        """Closed shell mesh at rest (topology :func:`bell_faces`): apex, the outer ellipsoid's
        rings down to the margin, the inner one's back up, the inner apex."""
        s = np.arange(1, MESH_RINGS + 1) / MESH_RINGS
        ring_s = np.concatenate([s, s[-2::-1]])
        outer = np.arange(len(ring_s)) < MESH_RINGS
        a = 0.5 * np.pi * ring_s
        r = np.where(outer, self.radius, self.radius - self.wall)
        h = np.where(outer, self.height, self.height - self.wall)
        rho = (r * np.sin(a))[:, None] * np.ones(self.sectors)
        z = (h * np.cos(a))[:, None] * np.ones(self.sectors)
        rings = np.stack(
            [rho * np.cos(self.sample_angles), rho * np.sin(self.sample_angles), z], axis=-1
        ).reshape(-1, 3)
        vertices = np.concatenate(
            [[[0.0, 0.0, self.height]], rings, [[0.0, 0.0, self.height - self.wall]]]
        )
        return vertices + self.centre

    def _skin_weights(self) -> sparse.csr_matrix:
        """(V, B) weights, rows summing to 1, of the particles within SKIN_RADIUS l0 of each rest
        vertex, ``(1 - d / r)^2`` (Eq. B12); the nearest particle if none is that close."""
        from scipy.spatial import cKDTree

        tree = cKDTree(self.rest)
        reach = SKIN_RADIUS * self.l0
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

    # The muscle and the springs (Eq. B8-B9).

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
        self._rest_length[:] = self.springs.rest_length
        self._rest_length[muscle] *= 1.0 - self.muscle_ratio * a
        self._stiffness[:] = self.stiffness
        self._stiffness[muscle] *= 1.0 + (self.muscle_stiffening - 1.0) * a
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
        run uses full stiffening throughout): ``SPRING_SAFETY x 2 / omega``, ``omega^2 = max_i 4
        sum_e k_e / m``, twice the block Gershgorin bound on the stiffness matrix's largest
        eigenvalue (each spring's 3 x 3 block ``k e e^T`` has norm k, so ``omega_max^2 <= max_i
        2 sum_e k_e / m`` whatever the springs' directions): docs/theory/soft-bell.md §4."""
        factor = 1.0 + max(self.muscle_stiffening - 1.0, 0.0) * activation
        total = self._passive_total + factor * self._muscle_total
        omega = math.sqrt(4.0 * float(total.max(initial=0.0)) / self.mass)
        return SPRING_SAFETY * 2.0 / omega if omega > 0 else math.inf

    # Records and the roots (Eq. B10-B11).

    def record(self, frame: int, positions: np.ndarray, velocities: np.ndarray) -> None:
        """Store the bell's state at ``frame`` and what it drives: roots, clamp directions, margin
        polyline, mean velocity. Only the last two frames are kept."""
        self.position = positions
        self.velocity = velocities
        margin = self._margin_weights @ positions
        margin_velocity = self._margin_weights @ velocities
        turn = self._meridian_angles(positions) - self._rest_meridian
        radial = margin - margin.mean(axis=0)
        radial[:, 2] = 0.0
        radial /= np.linalg.norm(radial, axis=1)[:, None]
        directions = np.sin(turn)[:, None] * radial
        directions[:, 2] -= np.cos(turn)
        take = slice(0, None, self.root_every) if self.tentacles else slice(0, 0)
        self.records[frame] = Record(
            margin[take],
            margin_velocity[take],
            directions[take],
            margin,
            velocities.mean(axis=0),
        )
        for old in [k for k in self.records if k < frame - 1]:
            del self.records[old]

    def _bracket(self, time: float) -> tuple[Record, Record, float]:
        frame = int(math.floor(time / self.frame_dt + 1e-9))
        if time - frame * self.frame_dt < 1e-9 * self.frame_dt and frame in self.records:
            frame -= 1  # a frame time belongs to the interval that ends there
        first = self.records.get(frame, self.records[max(self.records)])
        second = self.records.get(frame + 1, first)
        s = (time - frame * self.frame_dt) / self.frame_dt
        return first, second, float(np.clip(s, 0.0, 1.0))

    def roots(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cubic Hermite between the recorded frames (Eq. B11)."""
        h = self.frame_dt
        shape = (len(times), self.tentacles, 3)
        positions, velocities, directions = np.empty(shape), np.empty(shape), np.empty(shape)
        for n, t in enumerate(np.asarray(times, dtype=np.float64)):
            a, b, s = self._bracket(float(t))
            w, dw = _hermite(s)
            positions[n] = w[0] * a.roots + w[1] * h * a.velocities
            positions[n] += w[2] * b.roots + w[3] * h * b.velocities
            velocities[n] = dw[0] * a.roots + dw[1] * h * a.velocities
            velocities[n] += dw[2] * b.roots + dw[3] * h * b.velocities
            velocities[n] /= h
            d = (1.0 - s) * a.directions + s * b.directions
            directions[n] = d / np.linalg.norm(d, axis=1)[:, None]
        return positions, velocities, directions

    def bell_velocity(self, times: np.ndarray) -> np.ndarray:
        out = np.empty((len(times), 3))
        for n, t in enumerate(np.asarray(times, dtype=np.float64)):
            a, b, s = self._bracket(float(t))
            out[n] = (1.0 - s) * a.bell_velocity + s * b.bell_velocity
        return out

    def axis(self, times: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.array([0.0, 0.0, 1.0]), (np.size(times), 3)).copy()

    def margin(self, time: float) -> np.ndarray:
        a, b, s = self._bracket(time)
        return (1.0 - s) * a.margin + s * b.margin

    def forcing(self) -> Forcing:
        """The scales of a margin that loses ``muscle_ratio`` of its radius each pulse."""
        if self.muscle_ratio == 0.0:
            return Forcing(0.0, 0.0, 0.0)
        slope, curvature, period = waveform_peaks(self.waveform, self.jet_fraction)
        swing = self.radius * self.muscle_ratio
        return Forcing(
            swing * slope / self.period,
            swing * curvature / self.period**2,
            period * self.period,
        )

    # The body in the result.

    def surface(self) -> np.ndarray:
        """The rendering surface (V, 3) m at the current particle positions (Eq. B12)."""
        return self.rest_surface + self._skin @ (self.position - self.rest)

    def contraction(self) -> float:
        """1 - (mean margin radius now) / (at rest), from the margin polyline."""
        margin = self.records[max(self.records)].margin
        return 1.0 - _ring_radius(margin) / _ring_radius(self.records_rest_margin)

    @property
    def records_rest_margin(self) -> np.ndarray:
        return self._margin_weights @ self.rest

    def frame_datasets(self) -> list[Dataset]:
        return [
            Dataset("bell/position", (len(self.rest), 3), "m"),
            Dataset("bell/velocity", (len(self.rest), 3), "m/s"),
            Dataset("bell/surface_vertices", (len(self.rest_surface), 3), "m", np.float32),
            Dataset("bell/centre", (3,), "m"),
            Dataset("bell/contraction", (), "1"),
            Dataset("bell/activation", (), "1"),
        ]

    def frame_values(self, time: float) -> dict[str, np.ndarray]:
        return {
            "bell/position": self.position,
            "bell/velocity": self.velocity,
            "bell/surface_vertices": self.surface().astype(np.float32),
            "bell/centre": self.position.mean(axis=0),
            "bell/contraction": np.array(self.contraction()),
            "bell/activation": np.array(self.activation(time)),
        }

    def static_datasets(self) -> dict[str, tuple[np.ndarray, str]]:
        return {
            "bell/surface_faces": (self.faces, "1"),
            "bell/springs": (self.springs.pairs, "1"),
            "bell/muscle": (self.springs.muscle, "1"),
            "bell/rest_position": (self.rest, "m"),
        }

    def links(self) -> dict[str, str]:
        return {}


def _hermite(s: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Cubic Hermite basis (h00, h10, h01, h11) at s in [0, 1] and its derivatives in s."""
    return (
        (2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, 3 * s**2 - 2 * s**3, s**3 - s**2),
        (6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, 6 * s - 6 * s**2, 3 * s**2 - 2 * s),
    )


def _ring_radius(ring: np.ndarray) -> float:
    relative = ring - ring.mean(axis=0)
    return float(np.hypot(relative[:, 0], relative[:, 1]).mean())


@register("mass-spring")
def _mass_spring(scene: Scene) -> SoftBell:
    return SoftBell(scene)
