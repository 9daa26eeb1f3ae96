"""The soft bell's margin, recorded each frame, driving the tentacle roots (paper §4.2.4,
docs/theory/soft-bell.md §5, Eq. B10-B11).

Tentacle base points and the margin polyline are Gaussian-weighted means (over the arc, width
``MARGIN_SMOOTHING x l0``) of the lowest particle layer, recorded each frame with their velocities
and driven between frames by cubic Hermite interpolation (C1 in time). The clamp direction, -z at
rest, turns with the wall: with the mean of the third layer up, the meridian angle of (root -
upper point) is tracked. :class:`RecordedMargin` is the tentacles' root driver
(:class:`jellysim.tentacle.roots.RootDriver`).

The lowest layer's particles sit half a spacing inside the tissue that the skin draws (Eq. B12),
so a root at their mean would start its tentacle inside the bell's wall. Each margin root is
therefore moved along its clamp direction by ``drop``, the rest depth of its margin sample
inside the drawn surface (:func:`depth_inside`): at rest it sits on the underside of the drawn
margin, and the drop turns with the wall (issue 25: no tentacle through the bell). Under
``bell.root_placement = "edge"`` it is moved on, outward across its clamp direction by ``reach``,
to the drawn margin's outer edge, so that no drawn underside lies outside the root for the
margin's inward turn to sweep down over the chain (issues 25-26).

Mouth roots (oral arms) sit on their circle about the margin's centre in the margin plane at
rest. Under ``bell.arm_anchor = "subumbrella"`` the circle's centre is then carried by the drawn
underside's centre (the inner apex of the skin, Eq. B12) at a fixed stalk below it, the
manubrium, so that a bell whose margin rises above its own underside (pressed flat at the water's
surface) does not close over the arms' roots (Eq. B10c).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy import sparse

from jellysim.bell.soft import BellShape
from jellysim.tentacle.layout import RootLayout
from jellysim.tentacle.roots import Forcing

MARGIN_SMOOTHING = 1.5  # l0: standard deviation of the Gaussian along the margin arc
SAMPLE_SNAP = 1.0e-9  # of the sample step: a root angle this close to a sample takes the sample


class Record(NamedTuple):
    """What the bell drove the tentacles with at one frame: roots (T, 3) m and velocities m/s,
    clamp directions (T, 3), the margin polyline (R, 3) m, the bell's mean velocity (3,) m/s."""

    roots: np.ndarray
    velocities: np.ndarray
    directions: np.ndarray
    margin: np.ndarray
    bell_velocity: np.ndarray


class RecordedMargin:
    """The margin of a bell of ``shape`` whose particles rest at ``rest`` (B, 3) m on a lattice of
    spacing ``l0`` (m), sampled at ``sectors`` angles. The roots follow ``layout``: in a
    one-table scene every ``sectors // tentacles``-th sample is a root; otherwise a margin root
    is interpolated linearly in angle between the two samples about it, and a mouth root (oral
    arms) sits on its circle about the margin's centre in the margin plane, moving with the
    margin's mean velocity and hanging along -z, or with a mouth anchor (:meth:`set_mouth_anchor`)
    about the anchor's stalk. Frames are ``frame_dt`` (s) apart;
    ``forcing`` is the bell's (the scales of its pulse, for the tentacles' substep). ``drop``
    (R,) m per sample, zero until :meth:`set_drop`: how far a margin root lies along its clamp
    direction from the margin sample it is taken from (the module's docstring)."""

    def __init__(
        self,
        shape: BellShape,
        rest: np.ndarray,
        l0: float,
        sectors: int,
        layout: RootLayout,
        frame_dt: float,
        forcing: Forcing,
    ) -> None:
        self.sectors = sectors
        self.sample_angles = 2.0 * np.pi * np.arange(sectors) / sectors
        self.layout = layout
        tentacles = layout.count
        self.tentacles = tentacles
        self.root_every = sectors // tentacles if tentacles and layout.default else 0
        self.frame_dt = frame_dt
        self._forcing = forcing
        rho, height, angle = shape.cylindrical(rest)
        sigma = MARGIN_SMOOTHING * l0
        self._margin_weights = self._ring_weights(rho, angle, height < l0, sigma)
        self._upper_weights = self._ring_weights(
            rho, angle, (height >= 2 * l0) & (height < 3 * l0), sigma
        )
        self.rest_margin = self._margin_weights @ rest
        self.drop = np.zeros(sectors)
        self.reach = np.zeros(sectors)
        self._anchor: tuple[sparse.csr_matrix, np.ndarray, np.ndarray] | None = None
        self._rest_positions = rest
        self._rest_meridian = self._meridian_angles(rest)
        self.records: dict[int, Record] = {}
        self.record(0, rest, np.zeros_like(rest))

    def set_drop(self, drop: np.ndarray, reach: np.ndarray | None = None) -> None:
        """Move the margin roots by ``drop`` (R,) m along their clamp directions and, given
        ``reach`` (R,) m, outward across them in their meridian planes (the module's docstring),
        and record the rest frame again with it. With a reach the roots' velocities carry the
        turn of these offsets with the wall (Eq. B10b)."""
        self.drop = np.asarray(drop, dtype=np.float64)
        if reach is not None:
            self.reach = np.asarray(reach, dtype=np.float64)
        rest = self._rest_positions
        self.restart(0, rest, np.zeros_like(rest))

    def set_mouth_anchor(self, weights: sparse.csr_matrix, rest_point: np.ndarray) -> None:
        """Carry the mouth roots' circle from the point that rests at ``rest_point`` (3,) m and
        moves by ``weights`` (1, B) times the particles' displacement from rest (the drawn
        underside's centre, :meth:`jellysim.bell.skin.BellSkin.underside_centre`), at the stalk
        that joins it to the margin's centre at rest, and record the rest frame again with it
        (Eq. B10c)."""
        rest_point = np.asarray(rest_point, dtype=np.float64)
        self._anchor = (weights, rest_point, self.rest_margin.mean(axis=0) - rest_point)
        rest = self._rest_positions
        self.restart(0, rest, np.zeros_like(rest))

    def _ring_weights(
        self, rho: np.ndarray, angle: np.ndarray, layer: np.ndarray, sigma: float
    ) -> sparse.csr_matrix:
        """(R, B) weights, rows summing to 1: per sample angle, a Gaussian of width ``sigma`` (m)
        over the arc length to the particles of ``layer`` (Eq. B10)."""
        gap = np.angle(np.exp(1j * (angle[None, :] - self.sample_angles[:, None])))
        weights = np.exp(-0.5 * (gap * rho[None, :] / sigma) ** 2) * layer[None, :]
        weights[np.abs(gap * rho[None, :]) > 3.0 * sigma] = 0.0
        total = weights.sum(axis=1)
        if np.any(total <= 0.0):
            raise ValueError("the bell's margin layer has a gap: refine fluid.spacing")
        return sparse.csr_matrix(weights / total[:, None])

    def _meridian_angles(self, positions: np.ndarray) -> np.ndarray:
        """Per sample: the angle of (margin point - upper point) in its meridian plane (R,)."""
        _, chord, radial = self._chords(positions)
        return _meridian_angle(chord, radial)

    def _chords(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per sample: the margin point (R, 3) m, the chord (margin point - upper point) (R, 3) m
        and the sample's outward radial direction (R, 3)."""
        margin = self._margin_weights @ positions
        upper = self._upper_weights @ positions
        return margin, margin - upper, _radial(margin)

    def _turn_rates(
        self,
        chord: np.ndarray,
        radial: np.ndarray,
        margin_velocity: np.ndarray,
        velocities: np.ndarray,
    ) -> np.ndarray:
        """Per sample: the rate (R,) rad/s at which the meridian angle of ``chord`` turns, from
        the margin samples' velocity and the particles' ``velocities``: d/dt atan2(p, q) =
        (q p' - p q') / (p^2 + q^2) with p = chord . radial, q = -chord_z (the radial
        direction's own turn about the axis left out)."""
        d = chord
        rate = margin_velocity - self._upper_weights @ velocities
        p, q = np.einsum("ij,ij->i", d, radial), -d[:, 2]
        dp, dq = np.einsum("ij,ij->i", rate, radial), -rate[:, 2]
        return (q * dp - p * dq) / (p * p + q * q)

    def record(self, frame: int, positions: np.ndarray, velocities: np.ndarray) -> None:
        """Record what the bell particles at ``positions`` (B, 3) m moving at ``velocities``
        drive at ``frame``: roots, clamp directions, margin polyline, mean velocity (Eq. B10).
        Only the last two frames are kept."""
        margin, chord, radial = self._chords(positions)
        margin_velocity = self._margin_weights @ velocities
        turn = _meridian_angle(chord, radial) - self._rest_meridian
        directions = np.sin(turn)[:, None] * radial
        directions[:, 2] -= np.cos(turn)
        bases = margin + self.drop[:, None] * directions if self.drop.any() else margin
        base_velocity = margin_velocity
        if self.reach.any():
            # Eq. B10b: out across the clamp direction to the drawn margin's outer edge, and the
            # two offsets' turn with the wall in the velocity (d t/d turn = n, d n/d turn = -t).
            normals = np.cos(turn)[:, None] * radial
            normals[:, 2] += np.sin(turn)
            bases = bases + self.reach[:, None] * normals
            rate = self._turn_rates(chord, radial, margin_velocity, velocities)[:, None]
            base_velocity = margin_velocity + rate * (
                self.drop[:, None] * normals - self.reach[:, None] * directions
            )
        if self.root_every or not self.tentacles:
            take = slice(0, None, self.root_every) if self.tentacles else slice(0, 0)
            roots, root_velocities = bases[take], base_velocity[take]
            root_directions = directions[take]
        else:
            centre, centre_velocity = self._mouth_centre(
                margin, margin_velocity, positions, velocities
            )
            roots, root_velocities, root_directions = self._placed(
                bases, base_velocity, centre, centre_velocity, directions
            )
        self.records[frame] = Record(
            roots,
            root_velocities,
            root_directions,
            margin,
            velocities.mean(axis=0),
        )
        for old in [k for k in self.records if k < frame - 1]:
            del self.records[old]

    def _mouth_centre(
        self,
        margin: np.ndarray,
        margin_velocity: np.ndarray,
        positions: np.ndarray,
        velocities: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The centre (3,) m of the mouth roots' circle and its velocity (3,) m/s: the mean of
        the ``margin`` samples and of their ``margin_velocity``, or with a mouth anchor
        (:meth:`set_mouth_anchor`) the anchor moved with the particles at ``positions`` (B, 3)
        m and ``velocities``, plus the stalk (Eq. B10c)."""
        if self._anchor is None:
            return margin.mean(axis=0), margin_velocity.mean(axis=0)
        weights, rest_point, stalk = self._anchor
        moved = weights @ (positions - self._rest_positions)
        return rest_point + moved[0] + stalk, (weights @ velocities)[0]

    def _placed(
        self,
        bases: np.ndarray,
        base_velocity: np.ndarray,
        centre: np.ndarray,
        centre_velocity: np.ndarray,
        directions: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Roots, their velocities and clamp directions (T, 3) at the layout's places: margin
        roots between the samples' ``bases`` (the margin moved by the drop and the reach) moving
        at ``base_velocity``, mouth roots on their circle about ``centre`` (3,) m, moving at
        ``centre_velocity`` (3,) m/s and hanging along -z.

        A root whose angle falls on a sample (within 1e-9 of the sample step, as the even
        margin roots do) takes that sample itself, as one default group does: a group's roots
        are then the same bits whatever other groups the jellyfish carries."""
        layout = self.layout
        step = 2.0 * np.pi / self.sectors
        x = np.mod(layout.angles, 2.0 * np.pi) / step
        on_sample = np.abs(x - np.rint(x)) < SAMPLE_SNAP
        below = np.where(on_sample, np.rint(x), np.floor(x))
        j = below.astype(np.int64) % self.sectors
        w = np.where(on_sample, 0.0, x - below)[:, None]
        k = (j + 1) % self.sectors
        roots = (1.0 - w) * bases[j] + w * bases[k]
        root_velocities = (1.0 - w) * base_velocity[j] + w * base_velocity[k]
        d = (1.0 - w) * directions[j] + w * directions[k]
        root_directions = np.where(
            on_sample[:, None], directions[j], d / np.linalg.norm(d, axis=1)[:, None]
        )
        m = layout.mouth
        if np.any(m):
            radial = np.stack([np.cos(layout.angles[m]), np.sin(layout.angles[m])], axis=1)
            rest_radius = _ring_radius(self.rest_margin)
            roots[m] = centre
            roots[m, :2] += (layout.mouth_radius[m] * rest_radius)[:, None] * radial
            root_velocities[m] = centre_velocity
            root_directions[m] = (0.0, 0.0, -1.0)
        return roots, root_velocities, root_directions

    def restart(self, frame: int, positions: np.ndarray, velocities: np.ndarray) -> None:
        """Forget every record and record ``frame`` afresh (a resume from a checkpoint)."""
        self.records.clear()
        self.record(frame, positions, velocities)

    def _bracket(self, time: float) -> tuple[Record, Record, float]:
        frame = int(math.floor(time / self.frame_dt + 1e-9))
        if time - frame * self.frame_dt < 1e-9 * self.frame_dt and frame in self.records:
            frame -= 1  # a frame time belongs to the interval that ends there
        first = self.records.get(frame, self.records[max(self.records)])
        second = self.records.get(frame + 1, first)
        s = (time - frame * self.frame_dt) / self.frame_dt
        return first, second, float(np.clip(s, 0.0, 1.0))

    # RootDriver (Eq. B11).

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
        return self._forcing

    def contraction(self) -> float:
        """1 - (mean margin radius at the last record) / (at rest), from the margin polyline."""
        margin = self.records[max(self.records)].margin
        return 1.0 - _ring_radius(margin) / _ring_radius(self.rest_margin)


def _meridian_angle(chord: np.ndarray, radial: np.ndarray) -> np.ndarray:
    """The angle (R,) of each ``chord`` (R, 3) from straight down, towards its ``radial``
    direction (R, 3), in its meridian plane."""
    return np.arctan2(np.einsum("ij,ij->i", chord, radial), -chord[:, 2])


def _hermite(s: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Cubic Hermite basis (h00, h10, h01, h11) at s in [0, 1] and its derivatives in s."""
    return (
        (2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, 3 * s**2 - 2 * s**3, s**3 - s**2),
        (6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, 6 * s - 6 * s**2, 3 * s**2 - 2 * s),
    )


def _ring_radius(ring: np.ndarray) -> float:
    relative = ring - ring.mean(axis=0)
    return float(np.hypot(relative[:, 0], relative[:, 1]).mean())


def depth_inside(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """How far each point (N, 3) m lies inside the closed triangle surface (``vertices`` (V, 3),
    ``faces`` (F, 3)) straight below it: the distance down to the nearest crossing of the surface
    under the point when the point is inside (an odd number of crossings above it), else 0."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    v0, v1 = (b - a)[:, :2], (c - a)[:, :2]
    det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
    usable = np.abs(det) > 1e-300
    a, b, c, v0, v1, det = a[usable], b[usable], c[usable], v0[usable], v1[usable], det[usable]
    out = np.zeros(len(points))
    # a ray exactly along a mesh edge would cross its two triangles twice or not at all: look
    # a few 1e-9 of the surface's size aside
    nudge = np.array([1.37e-9, 2.71e-9]) * float(np.ptp(vertices, axis=0).max())
    for n, p in enumerate(np.asarray(points, dtype=np.float64)):
        q = p[:2] + nudge - a[:, :2]
        s = (q[:, 0] * v1[:, 1] - q[:, 1] * v1[:, 0]) / det
        t = (v0[:, 0] * q[:, 1] - v0[:, 1] * q[:, 0]) / det
        hit = (s >= 0.0) & (t >= 0.0) & (s + t <= 1.0)
        z = a[hit, 2] + s[hit] * (b - a)[hit, 2] + t[hit] * (c - a)[hit, 2]
        above, below = z[z > p[2]], z[z <= p[2]]
        if len(above) % 2 == 1 and len(below):
            out[n] = p[2] - below.max()
    return out


def edge_offsets(margin: np.ndarray, rim: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The drop (R,) m, straight down, and the reach (R,) m, outward along the sample's radial
    direction, that carry each sample of the rest ``margin`` (R, 3) m onto the drawn margin's
    outer edge ``rim`` (R, 3) m (one vertex per sample, at the sample's angle): the offsets that
    put a root on that edge (Eq. B10b)."""
    gap = rim - margin
    return -gap[:, 2], np.einsum("ij,ij->i", gap, _radial(margin))


def _radial(margin: np.ndarray) -> np.ndarray:
    """Each sample's outward horizontal direction (R, 3) from the centre of the ``margin``
    samples (R, 3) m."""
    radial = margin - margin.mean(axis=0)
    radial[:, 2] = 0.0
    radial /= np.linalg.norm(radial, axis=1)[:, None]
    return radial
