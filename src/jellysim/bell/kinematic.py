"""``bell.model = "kinematic"``: a rigid bell animated by a prescribed pulse (paper §4.2.1, Case 1).

The paper animates the Brown Jelly's bell by hand and lets its margin drive the tentacle roots.
Here the hand-keyed curves are replaced by a parametric bell (docs/theory/bell.md, Eq. B1-B6):

- Rest shape: a dome of revolution with meridian parameter s in [0, 1] (apex to margin),
  ``rho = R sin(pi s / 2)``, ``z = H cos(pi s / 2)`` (Eq. B1), margin at z = 0 in the bell frame;
  the inner (subumbrellar) surface is the outer one scaled by ``1 - thickness (1 - s^2)`` about the
  margin centre, so the shell is ``thickness x H`` thick at the apex and closes at the margin.
  Marginal lobes scallop the rim: ``rho *= 1 - lobe_depth w(theta) s^4`` with
  ``w = (1 - cos(lobes theta)) / 2`` (Eq. B2).
- Pulse: the contraction ``q(t) = contraction c(phase)`` with ``c`` in [0, 1] the waveform (Eq. B3):
  'jet' rises with a quintic smoothstep over ``jet_fraction`` of the period and falls with one over
  the rest, 'sine' is ``(1 - cos 2 pi phase) / 2``. Both are C2, so root velocities are C1.
  The shell deforms as ``rho *= 1 - q s^2`` and ``z *= 1 + elongation q`` (Eq. B4): the margin
  loses exactly the fraction q of its radius, the apex stays on the axis and the bell grows taller.
- Swimming: the bell moves along its axis (+z) at ``u = U (1 + k c'(phase))`` (Eq. B5), with U the
  mean ``swim_speed`` and k set so that the slowest speed, during relaxation, is
  ``(1 - speed_variation) U``: fastest while jetting, coasting while relaxing.
- Roots: on the margin at the layout's angles (tentacle k at ``2 pi k / T`` in a one-table
  scene; :mod:`jellysim.tentacle.layout`); the clamp direction keeps its initial angle (along
  -z) to the bell wall at the margin as the wall tilts inwards (Eq. B6). Mouth roots (oral arms)
  sit on their circle in the margin plane, carried with the bell, hanging along -z.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from jellysim import fields
from jellysim.bell import BellModel, register
from jellysim.config.schema import Scene
from jellysim.fields import Dataset
from jellysim.tentacle.layout import RootLayout, root_layout
from jellysim.tentacle.roots import NO_FORCING, Forcing

MESH_RINGS = 12  # meridian rings of each surface, apex excluded
MIN_SECTORS = 48  # vertices around the margin, at least
SECTORS_PER_LOBE = 4
Z_AXIS = np.array([0.0, 0.0, 1.0])
# (q, dq/dt, z, u) at a set of times, each (S,): see KinematicBell.motion.
Motion = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]

SMOOTHSTEP_PEAK_SLOPE = 1.875  # max of d/dx (6 x^5 - 15 x^4 + 10 x^3), at x = 1/2
SMOOTHSTEP_PEAK_CURVATURE = 10.0 / math.sqrt(3.0)  # max |d2/dx2|, at x = 1/2 -+ sqrt(3)/6


def smoothstep(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quintic smoothstep ``S = 6x^5 - 15x^4 + 10x^3`` on [0, 1] and its derivative; S' and S''
    vanish at both ends (C2 joins)."""
    x = np.clip(x, 0.0, 1.0)
    return x**3 * (10.0 + x * (-15.0 + 6.0 * x)), 30.0 * x**2 * (1.0 - x) ** 2


def contraction_waveform(
    phase: np.ndarray, waveform: str, jet_fraction: float
) -> tuple[np.ndarray, np.ndarray]:
    """The pulse ``c`` in [0, 1] (0 relaxed, 1 fully contracted) at ``phase`` in [0, 1) and its
    derivative ``dc/dphase`` (Eq. B3)."""
    phase = np.asarray(phase, dtype=np.float64)
    if waveform == "sine":
        return 0.5 * (1.0 - np.cos(2.0 * np.pi * phase)), np.pi * np.sin(2.0 * np.pi * phase)
    jetting = phase < jet_fraction
    rise, rise_slope = smoothstep(phase / jet_fraction)
    fall, fall_slope = smoothstep((phase - jet_fraction) / (1.0 - jet_fraction))
    c = np.where(jetting, rise, 1.0 - fall)
    slope = np.where(jetting, rise_slope / jet_fraction, -fall_slope / (1.0 - jet_fraction))
    return c, slope


def fastest_relaxation(waveform: str, jet_fraction: float) -> float:
    """The largest ``-dc/dphase`` of a waveform (its steepest relaxation)."""
    if waveform == "sine":
        return math.pi
    return SMOOTHSTEP_PEAK_SLOPE / (1.0 - jet_fraction)


def sector_count(tentacles: int, lobes: int) -> int:
    """Vertices around the margin: a multiple of the tentacle count (so every root is a vertex),
    at least MIN_SECTORS and SECTORS_PER_LOBE per lobe."""
    wanted = max(MIN_SECTORS, SECTORS_PER_LOBE * lobes)
    return tentacles * -(-wanted // tentacles)


def bell_faces(sectors: int, rings: int = MESH_RINGS) -> np.ndarray:
    """Triangles (M, 3) int32 of the closed bell shell, outward-facing (counter-clockwise seen
    from outside).

    Vertex 0 is the outer apex; then 2 rings - 1 rings of ``sectors`` vertices, outer from the
    apex down to the margin (ring rings - 1) and inner from the margin back up; last the inner
    apex.
    """
    ring_count = 2 * rings - 1
    inner_apex = 1 + ring_count * sectors
    j = np.arange(sectors)
    jn = (j + 1) % sectors

    def v(ring: int, k: np.ndarray) -> np.ndarray:
        return 1 + ring * sectors + k

    zeros = np.zeros(sectors, dtype=np.int64)
    faces = [np.stack([zeros, v(0, j), v(0, jn)], axis=1)]
    for ring in range(ring_count - 1):
        faces.append(np.stack([v(ring, j), v(ring + 1, j), v(ring + 1, jn)], axis=1))
        faces.append(np.stack([v(ring, j), v(ring + 1, jn), v(ring, jn)], axis=1))
    last = ring_count - 1
    faces.append(np.stack([v(last, j), zeros + inner_apex, v(last, jn)], axis=1))
    return np.concatenate(faces).astype(np.int32)


def waveform_peaks(waveform: str, jet_fraction: float) -> tuple[float, float, float]:
    """The largest ``|dc/dphase|`` and ``|d2c/dphase2|`` of a waveform, and the period (in
    periods) of a sine with the same shortest rise or fall."""
    if waveform == "sine":
        return math.pi, 2.0 * math.pi**2, 1.0
    shortest = min(jet_fraction, 1.0 - jet_fraction)
    return SMOOTHSTEP_PEAK_SLOPE / shortest, SMOOTHSTEP_PEAK_CURVATURE / shortest**2, 2.0 * shortest


class KinematicBell(BellModel):
    """A rigid, pulsing, swimming bell (:class:`jellysim.bell.BellModel`); times in s."""

    def __init__(
        self,
        *,
        radius: float,
        height: float,
        thickness: float,
        lobes: int,
        lobe_depth: float,
        period: float,
        contraction: float,
        waveform: str,
        jet_fraction: float,
        elongation: float,
        swim_speed: float,
        speed_variation: float,
        layout: RootLayout,
    ) -> None:
        self.radius = radius
        self.height = height
        self.thickness = thickness
        self.lobes = lobes
        self.lobe_depth = lobe_depth if lobes > 0 else 0.0
        self.period = period
        self.contraction = contraction
        self.waveform = waveform
        self.jet_fraction = jet_fraction
        self.elongation = elongation
        self.swim_speed = swim_speed
        self.speed_gain = speed_variation / fastest_relaxation(waveform, jet_fraction)
        self.sectors = sector_count(layout.margin_sectors(), lobes)
        self.faces = bell_faces(self.sectors)
        self.root_angles = layout.angles
        self.mouth = layout.mouth if layout.any_mouth else None
        self.mouth_radius = radius * layout.mouth_radius
        self.sector_angles = 2.0 * np.pi * np.arange(self.sectors) / self.sectors
        # Outer meridian s from the first ring to the margin, inner from the margin back up.
        outer = np.arange(1, MESH_RINGS + 1) / MESH_RINGS
        self.ring_s = np.concatenate([outer, outer[-2::-1]])
        self.ring_scale = np.concatenate(
            [np.ones(MESH_RINGS), 1.0 - thickness * (1.0 - outer[-2::-1] ** 2)]
        )
        self._surface_cache: tuple[float, np.ndarray] = (math.nan, np.empty((0, 3)))
        # Per root, constant: radial unit vector (T, 3), rest margin radius (T,), notch depth
        # (T,) and the rest angle psi0 of the wall at the margin (T,) (Eq. B2, B6).
        angles = self.root_angles
        depth = self.lobe_depth * self._notch(angles)
        self._root_constants = (
            np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1),
            radius * self._lobe_factor(1.0, angles),
            depth,
            np.arctan2(-4.0 * radius * depth, 0.5 * np.pi * height),
        )
        nothing = np.empty(0)
        self._motion_cache: tuple[np.ndarray, Motion] = (
            np.array([math.nan]),
            (nothing, nothing, nothing, nothing),
        )

    # The pulse and the swimming (Eq. B3-B5).

    def motion(self, times: np.ndarray) -> Motion:
        """At ``times`` (S,): the contraction ``q`` (fraction of the margin radius lost),
        ``dq/dt`` (1/s), the margin centre's position along the axis (m) and the swimming speed
        (m/s). ``z = U t + U T k c`` integrates ``u = U (1 + k c')`` exactly (Eq. B5).

        The last answer is kept: a frame asks for the same times several times (roots, bell
        velocity, surface)."""
        times = np.asarray(times, dtype=np.float64)
        last_times, last = self._motion_cache
        if times.shape == last_times.shape and np.array_equal(times, last_times):
            return last
        c, slope = contraction_waveform(
            np.mod(times / self.period, 1.0), self.waveform, self.jet_fraction
        )
        u = self.swim_speed
        motion: Motion = (
            self.contraction * c,
            self.contraction * slope / self.period,
            u * (times + self.period * self.speed_gain * c),
            u * (1.0 + self.speed_gain * slope),
        )
        self._motion_cache = (times.copy(), motion)
        return motion

    def _notch(self, angles: np.ndarray) -> np.ndarray:
        """``w(theta) = (1 - cos(lobes theta)) / 2``: 0 at a lobe's tip, 1 in a notch (Eq. B2)."""
        return 0.5 * (1.0 - np.cos(self.lobes * angles))

    def _lobe_factor(self, s: np.ndarray | float, angles: np.ndarray) -> np.ndarray:
        """``1 - lobe_depth w(theta) s^4`` (Eq. B2), broadcast over s and angles."""
        return 1.0 - self.lobe_depth * self._notch(angles) * np.asarray(s) ** 4

    # RootDriver.

    def roots(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        q, q_rate, z, u = self.motion(times)
        radial, rest_radius, depth, rest = self._root_constants
        positions = (rest_radius[None, :, None] * (1.0 - q)[:, None, None]) * radial[None]
        positions[..., 2] = z[:, None]
        velocities = -(rest_radius[None, :, None] * q_rate[:, None, None]) * radial[None]
        velocities[..., 2] = u[:, None]
        # Clamp direction (Eq. B6): the wall's meridian tangent at the margin turns by
        # psi - psi0, and the root direction (-z at rest) turns with it.
        q2 = q[:, None]
        d_rho = -self.radius * (2.0 * q2 * (1.0 - depth) + 4.0 * depth * (1.0 - q2))
        d_z = 0.5 * np.pi * self.height * (1.0 + self.elongation * q2)
        turn = np.arctan2(d_rho, d_z) - rest
        directions = np.sin(turn)[..., None] * radial[None] - np.cos(turn)[..., None] * Z_AXIS
        if self.mouth is not None:  # oral arms: carried with the bell, not with its margin
            m = self.mouth
            positions[:, m, :2] = self.mouth_radius[m, None] * radial[m, :2]
            velocities[:, m, :2] = 0.0
            directions[:, m] = -Z_AXIS
        return positions, velocities, directions

    def forcing(self) -> Forcing:
        """Radial margin motion plus the swing of the swimming speed about its mean."""
        if self.contraction == 0.0:
            return NO_FORCING
        slope, curvature, period = waveform_peaks(self.waveform, self.jet_fraction)
        margin = self.radius * self.contraction
        swing = self.swim_speed * self.speed_gain
        return Forcing(
            margin * slope / self.period + swing * slope,
            (margin / self.period + swing) * curvature / self.period,
            period * self.period,
        )

    def bell_velocity(self, times: np.ndarray) -> np.ndarray:
        return self.motion(times)[3][:, None] * Z_AXIS

    def axis(self, times: np.ndarray) -> np.ndarray:
        return np.broadcast_to(Z_AXIS, (np.size(times), 3)).copy()

    def margin(self, time: float) -> np.ndarray:
        """The outer surface's last ring: the roots are among its vertices."""
        first = 1 + (MESH_RINGS - 1) * self.sectors
        return self.surface(time)[first : first + self.sectors]

    # The body (Eq. B1-B4).

    def shell(self) -> tuple[Callable[[float], np.ndarray], np.ndarray]:
        return self.surface, self.faces

    def surface(self, time: float) -> np.ndarray:
        """Vertices (V, 3) m of the closed shell at ``time`` (topology :attr:`faces`)."""
        if self._surface_cache[0] == time:
            return self._surface_cache[1]
        q, _, z0, _ = (float(value[0]) for value in self.motion(np.array([time])))
        stretch = 1.0 + self.elongation * q
        a = 0.5 * np.pi * self.ring_s  # (rings,)
        rho = (
            self.radius
            * (self.ring_scale * np.sin(a) * (1.0 - q * self.ring_s**2))[:, None]
            * self._lobe_factor(self.ring_s[:, None], self.sector_angles[None, :])
        )
        z = np.broadcast_to(
            (self.height * stretch * self.ring_scale * np.cos(a))[:, None], rho.shape
        )
        rings = np.stack(
            [rho * np.cos(self.sector_angles), rho * np.sin(self.sector_angles), z], axis=-1
        ).reshape(-1, 3)
        top = self.height * stretch
        vertices = np.concatenate(
            [[[0.0, 0.0, top]], rings, [[0.0, 0.0, top * (1.0 - self.thickness)]]]
        )
        vertices[:, 2] += z0
        self._surface_cache = (time, vertices)
        return vertices

    def inside(self, points: np.ndarray, time: float) -> np.ndarray:
        """Whether each point (..., 3) lies strictly under the outer surface, in the shell or
        its cavity, at ``time``: where no tentacle may go."""
        q, _, z0, _ = (float(value[0]) for value in self.motion(np.array([time])))
        top = self.height * (1.0 + self.elongation * q)
        rel_z = points[..., 2] - z0
        within = (rel_z > 0.0) & (rel_z < top)
        a = np.arccos(np.clip(rel_z / top, -1.0, 1.0))
        s = 2.0 * a / np.pi
        angles = np.arctan2(points[..., 1], points[..., 0])
        wall = self.radius * np.sin(a) * (1.0 - q * s**2) * self._lobe_factor(s, angles)
        return within & (np.hypot(points[..., 0], points[..., 1]) < wall)

    def frame_datasets(self) -> list[Dataset]:
        vertices = 2 + (2 * MESH_RINGS - 1) * self.sectors
        return [
            fields.BELL_SURFACE_VERTICES.dataset(V=vertices),
            fields.BELL_CENTRE.dataset(),
            fields.BELL_CONTRACTION.dataset(),
        ]

    def frame_values(self, time: float) -> dict[str, np.ndarray]:
        q, _, z0, _ = (float(value[0]) for value in self.motion(np.array([time])))
        return {
            fields.BELL_SURFACE_VERTICES.path: self.surface(time).astype(np.float32),
            fields.BELL_CENTRE.path: np.array([0.0, 0.0, z0]),
            fields.BELL_CONTRACTION.path: np.array(q),
        }

    def static_datasets(self) -> dict[str, tuple[np.ndarray, str]]:
        return {fields.BELL_SURFACE_FACES.path: (self.faces, fields.BELL_SURFACE_FACES.units)}

    def links(self) -> dict[str, str]:
        return {fields.BELL_POSITION.path: fields.BELL_SURFACE_VERTICES.path}


@register("kinematic")
def _kinematic(scene: Scene) -> KinematicBell:
    b = scene.bell
    return KinematicBell(
        radius=b.radius,
        height=b.height,
        thickness=b.thickness,
        lobes=b.lobes,
        lobe_depth=b.lobe_depth,
        period=b.period,
        contraction=b.contraction,
        waveform=b.waveform,
        jet_fraction=b.jet_fraction,
        elongation=b.elongation,
        swim_speed=b.swim_speed,
        speed_variation=b.speed_variation,
        layout=root_layout(scene),
    )
