"""Cosine interpolation of tentacles (paper §4.1.3): many drawn tentacles from a few simulated.

A render-time operation on a result, never part of the physics state. Between neighbouring
simulated tentacles k and k+1 around the rim (the last wrapping to the first), drawn tentacle
j = 0..N-1 at fraction ``t = j / N`` gets (docs/theory/interpolation.md):

- its root on the margin, at the angle ``phi_k + t (phi_{k+1} - phi_k)`` about the bell axis,
- its shape blended in each root's local frame (radial, tangential, axial) with the paper's
  cosine weight ``w = (1 - cos(pi t)) / 2``: ``s = (1 - w) s_k + w s_{k+1}``; for curled
  tentacles (a scene with a rest curvature) the chains' discrete curvature vectors in Bishop
  frames are blended instead and the drawn chain is rebuilt from them (:data:`SHAPE_SPACES`),
- its segment lengths restored to d by walking the blended polyline from the root,
- a time lag that breaks up the banding of cosine weights (shapes bunch near the simulated
  tentacles): every other drawn tentacle shows its shape ``lag`` earlier, so that neighbours
  always differ by about as much; simulated tentacles keep lag 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from jellysim import fields
from jellysim.config.schema import Scene, Tentacles
from jellysim.tentacle.layout import DEFAULT_CLUSTERS, root_layout
from jellysim.tentacle.model import curl_normals, rest_shape_for


def cosine_weight(t: np.ndarray) -> np.ndarray:
    """The paper's cosine interpolation weight, ``(1 - cos(pi t)) / 2`` for t in [0, 1]."""
    return 0.5 * (1.0 - np.cos(np.pi * np.asarray(t, dtype=np.float64)))


def local_frames(roots: np.ndarray, centre: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Orthonormal frames (..., 3, 3) at ``roots`` (..., 3): rows radial, tangential, axial.

    ``centre`` and ``axis`` broadcast against ``roots``.
    """
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    radial = roots - centre
    radial = radial - np.sum(radial * axis, axis=-1, keepdims=True) * axis
    norm = np.linalg.norm(radial, axis=-1, keepdims=True)
    # A root on the axis has no radial direction: take one perpendicular to the axis.
    helper = np.where(np.abs(axis[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    fallback = np.cross(axis, helper)
    fallback = fallback / np.linalg.norm(fallback, axis=-1, keepdims=True)
    radial = np.where(norm > 1e-12, radial / np.maximum(norm, 1e-300), fallback)
    axis = np.broadcast_to(axis, radial.shape)
    tangential = np.cross(axis, radial)
    return np.stack([radial, tangential, axis], axis=-2)


def _angles(points: np.ndarray, centre: np.ndarray, frame0: np.ndarray) -> np.ndarray:
    rel = points - centre
    return np.arctan2(rel @ frame0[1], rel @ frame0[0])


def margin_point(
    margin: np.ndarray, centre: np.ndarray, frame0: np.ndarray, angles: np.ndarray
) -> np.ndarray:
    """Points of the closed polyline ``margin`` (R, 3) at ``angles`` about the centre.

    The margin is star-shaped about its centre (true of a bell's rim): the point at angle phi is
    where the polyline crosses that half-plane, linearly between its vertices.
    """
    vertex_angles = np.unwrap(_angles(margin, centre, frame0))
    closed = np.vstack([margin, margin[:1]])
    turn = np.sign(vertex_angles[-1] - vertex_angles[0]) or 1.0
    closed_angles = np.append(vertex_angles, vertex_angles[0] + turn * 2.0 * np.pi)
    if turn < 0:
        closed, closed_angles = closed[::-1], closed_angles[::-1]
    start = closed_angles[0]
    wrapped = start + np.mod(np.asarray(angles) - start, 2.0 * np.pi)
    index = np.clip(np.searchsorted(closed_angles, wrapped) - 1, 0, len(closed) - 2)
    # Where the ray from the centre at that angle crosses the edge (in the margin's plane).
    p0, p1 = closed[index] - centre, closed[index + 1] - centre
    a0 = np.stack([p0 @ frame0[0], p0 @ frame0[1]], axis=-1)
    b = np.stack([(p1 - p0) @ frame0[0], (p1 - p0) @ frame0[1]], axis=-1)
    u = np.stack([np.cos(wrapped), np.sin(wrapped)], axis=-1)
    cross_ua = u[..., 0] * a0[..., 1] - u[..., 1] * a0[..., 0]
    cross_ub = u[..., 0] * b[..., 1] - u[..., 1] * b[..., 0]
    f = np.clip(-cross_ua / np.where(cross_ub == 0.0, 1.0, cross_ub), 0.0, 1.0)[..., None]
    return centre + (1.0 - f) * p0 + f * p1


def interpolation_lags(count: int, factor: int, spread: float) -> np.ndarray:
    """Time lag (s) of each drawn tentacle: simulated ones 0, the others alternately
    ``spread`` and 0 around the rim, so that every pair of neighbours differs by the same lag
    (for an odd factor the last one before each simulated tentacle takes ``spread / 2``)."""
    slot = np.arange(count * factor) % factor
    lags = np.where(slot % 2 == 1, spread, 0.0)
    if factor % 2 == 1 and factor > 1:
        lags[slot == factor - 1] = 0.5 * spread
    return lags


class ShapeSpace(Protocol):
    """Coordinates in which the shapes of simulated tentacles are blended.

    ``encode`` takes shapes (N, P, 3), m, in their roots' local frames (root at the origin) and
    returns coordinates (N, Q, 3) that are blended linearly (in time between frames, then with
    the cosine weights between neighbours); ``decode`` turns blended coordinates back into
    local shapes (N, P, 3), m, which are then placed at the drawn roots and walked to lengths d.
    """

    def encode(self, shapes: np.ndarray) -> np.ndarray: ...

    def decode(self, coordinates: np.ndarray, spacing: float) -> np.ndarray: ...


class Positions:
    """Blend the particle positions themselves (docs/theory/interpolation.md, step 2)."""

    def encode(self, shapes: np.ndarray) -> np.ndarray:
        return shapes

    def decode(self, coordinates: np.ndarray, spacing: float) -> np.ndarray:
        return coordinates


RADIAL = np.array([1.0, 0.0, 0.0])  # the outward radial direction in a root's local frame
AXIAL = np.array([0.0, 0.0, 1.0])  # the bell axis in a root's local frame
MAX_CURVATURE_GAIN = 2.0  # Eq. (I3): at most this rescaling of a blended curvature vector


def bishop_normals(tangents: np.ndarray) -> np.ndarray:
    """Root normals (N, 3) of Bishop frames for first tangents (N, 3) in local frames: the
    outward radial direction made perpendicular to the tangent, as the rest shape's root frame
    (docs/theory/tentacle.md §6; the bell axis where the tangent points outward)."""
    normals = curl_normals(
        tangents[None],
        np.broadcast_to(RADIAL, tangents.shape)[None],
        AXIAL[None],
    )
    return normals[0]


def bishop_step(
    tangent: np.ndarray, normal: np.ndarray, curvature: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Turn the Bishop frame (tangent, normal) (N, 3) by the discrete curvature vector
    ``curvature`` (N, 2), rad, in the (normal, binormal) plane, Eq. (I2): the rotation by
    theta = |c| about the axis t x u, u = (c_n n + c_b b) / theta, which takes t to
    ``cos theta t + sin theta u`` and transports the normal without twist (Eq. T11)."""
    binormal = np.cross(tangent, normal)
    theta = np.linalg.norm(curvature, axis=1)
    safe = np.where(theta > 0.0, theta, 1.0)
    cos_phi = np.where(theta > 0.0, curvature[:, 0] / safe, 1.0)[:, None]
    sin_phi = np.where(theta > 0.0, curvature[:, 1] / safe, 0.0)[:, None]
    bend = cos_phi * normal + sin_phi * binormal
    cos_t, sin_t = np.cos(theta)[:, None], np.sin(theta)[:, None]
    new_tangent = cos_t * tangent + sin_t * bend
    new_normal = normal + cos_phi * ((cos_t - 1.0) * bend - sin_t * tangent)
    return new_tangent, new_normal


def best_rotation(moving: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Rotations (N, 3, 3) about the origin that best fit the point sets ``moving`` (N, P, 3)
    onto ``target`` (N, P, 3) in the least-squares sense (Kabsch): R = V diag(1, 1, det) U^T
    from the SVD U S V^T of sum_p moving_p target_p^T, Eq. (I4)."""
    u, _, vt = np.linalg.svd(np.einsum("npi,npj->nij", moving, target))
    sign = np.ones(moving.shape[0:1] + (3,))
    sign[:, 2] = np.sign(np.linalg.det(np.einsum("nij,njk->nik", u, vt)))
    return np.einsum("nji,nj,nkj->nik", vt, sign, u)


class BishopCurvatures:
    """Blend discrete curvature vectors in Bishop frames and rebuild the chain, Eq. (I2-I4).

    Coordinates (N, 2P - 1, 3): rows 0..P-1 the positions (placed as for :class:`Positions`),
    then row P the first segment's unit tangent and rows P+1..2P-2 at node i = 1..P-2 the
    curvature vector c_i = theta_i (cos phi_i, sin phi_i) (the turning angle theta_i, rad,
    between segments i-1 and i, towards the direction phi_i from the transported normal) and,
    third, theta_i. Blending the third channel gives the mean turning angle, to which the
    blended vector is rescaled (Eq. I3), so that coils whose bends point in different directions
    blend into a coil of the same curvature, never into a zigzag. The chain rebuilt from the
    curvatures is then turned rigidly about its root onto the blended positions (Eq. I4): the
    walk alone lets small differences near the root swing the far end away from both
    neighbours.
    """

    def encode(self, shapes: np.ndarray) -> np.ndarray:
        segments = np.diff(shapes, axis=1)
        tangents = segments / np.linalg.norm(segments, axis=2, keepdims=True)
        out = np.zeros((shapes.shape[0], shapes.shape[1] - 1, 3))
        out[:, 0] = tangents[:, 0]
        normal = bishop_normals(tangents[:, 0])
        for i in range(1, tangents.shape[1]):
            before, after = tangents[:, i - 1], tangents[:, i]
            binormal = np.cross(before, normal)
            along_n = np.sum(after * normal, axis=1)
            along_b = np.sum(after * binormal, axis=1)
            sin_t = np.hypot(along_n, along_b)
            theta = np.arctan2(sin_t, np.sum(after * before, axis=1))
            scale = np.where(sin_t > 0.0, theta / np.where(sin_t > 0.0, sin_t, 1.0), 1.0)
            out[:, i, 0] = scale * along_n
            out[:, i, 1] = scale * along_b
            out[:, i, 2] = theta
            _, normal = bishop_step(before, normal, out[:, i, :2])
        return np.concatenate([shapes, out], axis=1)

    def decode(self, coordinates: np.ndarray, spacing: float) -> np.ndarray:
        particles = (coordinates.shape[1] + 1) // 2
        positions, intrinsic = coordinates[:, :particles], coordinates[:, particles:]
        chain = self.walk(intrinsic, spacing)
        return np.einsum("nij,npj->npi", best_rotation(chain, positions), chain)

    @staticmethod
    def walk(intrinsic: np.ndarray, spacing: float) -> np.ndarray:
        """The chain (N, P, 3), m, from its root at the origin, of segments of length
        ``spacing`` turned by the blended curvature vectors ``intrinsic`` (N, P - 1, 3) rescaled
        by Eq. (I3)."""
        tangent = intrinsic[:, 0] / np.linalg.norm(intrinsic[:, 0], axis=1, keepdims=True)
        normal = bishop_normals(tangent)
        vectors = intrinsic[:, 1:, :2]
        size = np.linalg.norm(vectors, axis=2)
        gain = np.minimum(intrinsic[:, 1:, 2] / np.where(size > 0.0, size, 1.0), MAX_CURVATURE_GAIN)
        curvature = vectors * np.where(size > 0.0, gain, 1.0)[..., None]
        out = np.zeros((intrinsic.shape[0], intrinsic.shape[1] + 1, 3))
        out[:, 1] = spacing * tangent
        for i in range(curvature.shape[1]):
            tangent, normal = bishop_step(tangent, normal, curvature[:, i])
            out[:, i + 2] = out[:, i + 1] + spacing * tangent
        return out


SHAPE_SPACES: dict[str, ShapeSpace] = {
    "positions": Positions(),
    "curvatures": BishopCurvatures(),
}


def interpolate_tentacles(
    positions: np.ndarray,
    margin: np.ndarray,
    times: np.ndarray,
    factor: int,
    spacing: float,
    axis: np.ndarray | None = None,
    lag_spread: float = 0.0,
    first: int = 0,
    shape_space: str = "positions",
    closed: bool = True,
) -> np.ndarray:
    """Drawn tentacles (F - first, T * factor, P, 3) from simulated ones (F, T, P, 3).

    ``closed`` (default): the roots go round the bell, the last blending into the first. An open
    row of roots (one cluster of a group, ``closed=False``) draws (T - 1) * factor + 1
    tentacles, none after the last simulated one.

    ``margin`` (F, R, 3) is the margin polyline per frame, ``times`` (F,) the frame times (s),
    ``axis`` the bell axis (default +z, or (F, 3) per frame), ``spacing`` d (m), ``lag_spread``
    the largest time lag (s) of a drawn tentacle (0 turns the lags off). Frames before
    ``first`` are read (the lagged shapes of later frames reach back to them) but not drawn.
    Drawn tentacle ``k * factor`` is simulated tentacle k, unchanged. ``shape_space`` names the
    coordinates in which shapes are blended (:data:`SHAPE_SPACES`): "positions" (straight
    tentacles) or "curvatures" (curled ones).
    """
    positions = np.asarray(positions, dtype=np.float64)
    n_frames, count, particles, _ = positions.shape
    if factor < 1:
        raise ValueError("factor must be >= 1")
    if shape_space not in SHAPE_SPACES:
        raise ValueError(f"shape_space={shape_space!r}: expected one of {sorted(SHAPE_SPACES)}")
    space = SHAPE_SPACES[shape_space]
    if not 0 <= first < n_frames:
        raise ValueError(f"first={first}: expected 0 to {n_frames - 1}")
    axes = np.broadcast_to(
        np.array([0.0, 0.0, 1.0]) if axis is None else np.asarray(axis, dtype=np.float64),
        (n_frames, 3),
    )
    drawn = count * factor if closed else (count - 1) * factor + 1
    t = (np.arange(drawn) % factor) / factor
    weight = cosine_weight(t)
    left = np.arange(drawn) // factor
    right = (left + 1) % count
    lags = interpolation_lags(count, factor, lag_spread)[:drawn]

    # Shapes in each simulated root's local frame, per frame: (F, T, P, 3).
    centres = margin.mean(axis=1)
    roots = positions[:, :, 0]
    frames_sim = local_frames(roots, centres[:, None], axes[:, None])
    shapes = np.einsum("ftij,ftpj->ftpi", frames_sim, positions - roots[:, :, None])
    shapes = space.encode(shapes.reshape(-1, *shapes.shape[2:])).reshape(n_frames, count, -1, 3)

    # Shapes at lagged times of the frames drawn: linear in time between stored frames, held
    # at the ends.
    sample = np.clip(
        np.interp(times[first:, None] - lags[None, :], times, np.arange(n_frames)),
        0,
        n_frames - 1,
    )
    lo = np.floor(sample).astype(np.int64)
    hi = np.minimum(lo + 1, n_frames - 1)
    frac = (sample - lo)[..., None, None]

    def lagged(k: np.ndarray) -> np.ndarray:
        return (1.0 - frac) * shapes[lo, k] + frac * shapes[hi, k]

    blended = (1.0 - weight)[None, :, None, None] * lagged(left) + weight[
        None, :, None, None
    ] * lagged(right)
    blended = space.decode(blended.reshape(-1, *blended.shape[2:]), spacing).reshape(
        n_frames - first, drawn, particles, 3
    )

    out = np.empty((n_frames - first, drawn, particles, 3))
    for i, f in enumerate(range(first, n_frames)):
        frame0 = local_frames(roots[f, 0], centres[f], axes[f])
        phi = np.unwrap(_angles(roots[f], centres[f], frame0))
        step = np.mod(np.roll(phi, -1) - phi, 2.0 * np.pi)
        if count == 1:
            step[:] = 2.0 * np.pi
        angle = phi[left] + t * step[left]
        new_roots = margin_point(margin[f], centres[f], frame0, angle)
        new_roots[t == 0] = roots[f, left[t == 0]]  # simulated roots exactly
        frames_new = local_frames(new_roots, centres[f], axes[f])
        world = np.einsum("tij,tpi->tpj", frames_new, blended[i])  # back from local frames
        segments = np.diff(world, axis=1)
        lengths = np.linalg.norm(segments, axis=2, keepdims=True)
        units = segments / np.maximum(lengths, 1e-300)
        out[i, :, 0] = new_roots
        out[i, :, 1:] = new_roots[:, None] + spacing * np.cumsum(units, axis=1)
    # Simulated tentacles are drawn exactly as simulated.
    simulated = np.arange(0, drawn, factor)
    out[:, simulated] = positions[first:]
    return out


LAG_FRACTION_OF_PULSE = 0.25  # default lag: a quarter of the pulse period


def pulse_period(scene: object) -> float:
    """The period (s) of the root forcing of a scene: the root motion's for bell.model "none"."""
    bell = scene.bell  # type: ignore[attr-defined]
    if bell.model == "none":
        frequency = scene.root_motion.frequency  # type: ignore[attr-defined]
        return 1.0 / frequency if frequency > 0.0 else float(bell.period)
    return float(bell.period)


class TentacleFrames(Protocol):
    """What :func:`interpolate_result` reads of a result (:class:`jellysim.io.result.Result`
    keeps it): its scene, frame times (F,) s, and a field's frames."""

    @property
    def scene(self) -> Scene: ...

    @property
    def time(self) -> np.ndarray: ...

    def read(self, field: fields.Field, frames: Any = None) -> np.ndarray: ...


@dataclass(frozen=True)
class DrawnGroup:
    """One group's drawn tentacles: ``positions`` (F, D, P, 3) m, D drawn of P particles (the
    group's own), ``simulated`` the group's rows among the simulated tentacles, ``tentacles``
    the group's keys (its look: form, color, drawn_radius, taper, ribbon_width, ruffles,
    ruffle_depth), ``index`` its number in the result's ``tentacle_groups``."""

    name: str
    index: int
    tentacles: Tentacles
    positions: np.ndarray
    simulated: slice


MOUTH_CIRCLE_POINTS = 96  # vertices of the polygon the mouth roots' interpolation follows


def _mouth_circle(margin: np.ndarray, roots: np.ndarray) -> np.ndarray:
    """(F, R, 3): the circle through a mouth group's roots (F, T, 3), about the margin's centre
    in the plane perpendicular to z, on which the drawn roots are placed."""
    centre = margin.mean(axis=1)  # (F, 3)
    rel = roots - centre[:, None]
    radius = np.linalg.norm(rel[..., :2], axis=2).mean(axis=1)  # (F,)
    height = rel[..., 2].mean(axis=1)
    a = 2.0 * np.pi * np.arange(MOUTH_CIRCLE_POINTS) / MOUTH_CIRCLE_POINTS
    ring = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)  # (R, 3)
    out = centre[:, None] + radius[:, None, None] * ring[None]
    out[..., 2] += height[:, None]
    return out


def cluster_sizes(t: Tentacles) -> list[int]:
    """Sizes of a group's clusters of roots (one closed ring unless arranged in clusters)."""
    if t.arrangement != "clusters" or t.angles is not None:
        return [t.count]
    c = DEFAULT_CLUSTERS if t.clusters is None else t.clusters
    sizes = [t.count // c + (1 if j < t.count % c else 0) for j in range(c)]
    return [m for m in sizes if m > 0]


def interpolate_groups(
    result: TentacleFrames,
    factor: int | None = None,
    lag: float | None = None,
    frames: tuple[int, int] | None = None,
) -> list[DrawnGroup]:
    """Drawn tentacles of an open result, group by group (docs/groups.md).

    Each group is interpolated on its own, never blended with another: with its own
    ``interpolation`` (``factor`` overrides every thread group's; ribbon groups, oral arms,
    keep their own), its own particle count, its roots'
    ring (the margin, or for oral arms the circle through their roots), and in clusters each
    cluster as an open row (no tentacles drawn in the gaps between clusters). ``lag`` and
    ``frames`` as :func:`interpolate_result`.
    """
    scene = result.scene
    groups = scene.groups
    lag = LAG_FRACTION_OF_PULSE * pulse_period(scene) if lag is None else lag
    times = result.time
    start, stop = (0, times.shape[0]) if frames is None else frames
    if not 0 <= start < stop <= times.shape[0]:
        raise ValueError(f"frames {start}:{stop} outside 0:{times.shape[0]}")
    # The earliest frame a lagged shape of frame `start` reads (interpolate_tentacles holds the
    # shapes at the first frame before that, so the window must begin at or before it).
    first = max(0, int(np.searchsorted(times, times[start] - max(lag, 0.0), side="right")) - 1)
    window = slice(first, stop)
    positions = result.read(fields.TENTACLE_POSITION, window)
    margin = result.read(fields.BELL_MARGIN, window)
    layout = root_layout(scene)
    drawn_groups = []
    for index, (group, rows) in enumerate(zip(groups, layout.slices(), strict=True)):
        t = group.tentacles
        own = positions[:, rows, : t.particles]
        ring = _mouth_circle(margin, own[:, :, 0]) if t.placement == "mouth" else margin
        curled = bool(np.any(rest_shape_for(scene.group_scene(index)) != 0.0))
        # ``factor`` (render --interpolation) multiplies threads; ribbons (oral arms) keep their
        # group's own count: a frilled curtain per arm, not fifty.
        f = t.interpolation if factor is None or t.form == "ribbon" else factor
        sizes = cluster_sizes(t)
        parts = []
        edge = 0
        for size in sizes:
            parts.append(
                interpolate_tentacles(
                    own[:, edge : edge + size],
                    ring,
                    times[first:stop],
                    f,
                    t.spacing,
                    lag_spread=lag,
                    first=start - first,
                    shape_space="curvatures" if curled else "positions",
                    closed=len(sizes) == 1,
                )
            )
            edge += size
        drawn = parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)
        drawn_groups.append(DrawnGroup(group.name, index, t, drawn, rows))
    return drawn_groups


def gather_groups(drawn: list[DrawnGroup]) -> np.ndarray:
    """The groups' drawn tentacles as one array (F, D, P, 3), P the longest chain's, the rows
    beyond a shorter chain's own NaN; one group's array as it is."""
    if len(drawn) == 1:
        return drawn[0].positions
    frames = drawn[0].positions.shape[0]
    count = sum(g.positions.shape[1] for g in drawn)
    particles = max(g.positions.shape[2] for g in drawn)
    out = np.full((frames, count, particles, 3), np.nan)
    row = 0
    for g in drawn:
        d, p = g.positions.shape[1:3]
        out[:, row : row + d, :p] = g.positions
        row += d
    return out


def drawn_group_index(drawn: list[DrawnGroup]) -> np.ndarray:
    """The group (index into ``tentacle_groups``) of each row of :func:`gather_groups`."""
    return np.concatenate([np.full(g.positions.shape[1], g.index, dtype=np.int32) for g in drawn])


def interpolate_result(
    result: TentacleFrames,
    factor: int | None = None,
    lag: float | None = None,
    frames: tuple[int, int] | None = None,
) -> np.ndarray:
    """Drawn tentacles (F, D, P, 3) of an open result: every group's
    (:func:`interpolate_groups`), gathered by :func:`gather_groups`. A one-group scene draws
    T * factor tentacles.

    ``factor`` defaults to each group's ``interpolation``; ``lag`` (s) to a quarter of the pulse
    period (0 turns the anti-banding lag off). ``frames`` = (start, stop) gives only those
    frames, (stop - start, D, P, 3), equal to the slice of the whole: it reads the frames from
    ``lag`` before ``start`` on, which the lagged shapes need, and no others, and draws only
    the frames asked for.
    """
    return gather_groups(interpolate_groups(result, factor, lag, frames))
