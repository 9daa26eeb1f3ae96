"""How a result's tentacles move, in numbers an animator can read (issue 25, "Motion that reads
on screen"): how far they bend away from straight, and how long a motion of the root takes to
reach the tip.

For each frame and tentacle, with root x_0, tip x_{P-1} (the tentacle's own last particle) and
length L = (P - 1) d:

- ``chord``: |x_{P-1} - x_0| / L, 1 for a straight tentacle;
- ``bend``: the mean distance of the particles from the root-to-tip line, over L (0 straight;
  a half circle gives 2 / pi^2 ~ 0.2, see tests/unit/test_motion.py);
- ``lag``: how long the tip's sideways motion follows the root's. Sideways is horizontal, along
  the direction in which each root moves most (the principal axis of its horizontal motion:
  radial for a pulsing bell, the forcing's direction for a forced root), measured from the rim's
  centroid when there are three tentacles or more (so that a drifting bell does not count). At
  the root motion's dominant frequency f, the tip's phase behind the root's, as a delay in
  [0, 1/f): 0 for a curtain that moves rigidly, L / c for a wave running down a tentacle of
  length L at speed c (modulo the period).

Statistics are taken over the second half of the run by default (after the start-up transient),
over every tentacle or over one group's (:func:`motion_by_group`); each chain is measured over its
own particles, never the NaN rows that pad a group of shorter chains in the result.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jellysim import fields
from jellysim.io.result import Result


@dataclass(frozen=True)
class Motion:
    """The tentacles' motion over ``start``..``end`` (s) of a result."""

    start: float
    end: float
    chord: float  # mean root-to-tip distance over length, 1 straight
    bend: float  # mean distance from the root-to-tip line over length, 0 straight
    bend_peak: float  # the largest per-frame mean of ``bend`` over the tentacles
    lag: float  # s, root-to-tip delay of the sideways motion, in [0, period)
    period: float  # s, the period of the root's dominant sideways motion
    coherence: float  # in [0, 1]: how steadily the tip follows the root with that delay

    def describe(self) -> str:
        return (
            f"tentacles over {self.start:.3g}-{self.end:.3g} s: chord {self.chord:.3f} of their "
            f"length, bend {100 * self.bend:.1f} % (peak {100 * self.bend_peak:.1f} %), "
            f"root-to-tip lag {self.lag:.3g} s of a {self.period:.3g} s period (coherence "
            f"{self.coherence:.2f})"
        )


def chord_and_bend(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``chord`` and ``bend`` (both (...,)) of chains ``positions`` (..., P, 3)."""
    x = np.asarray(positions, dtype=np.float64)
    segments = np.linalg.norm(np.diff(x, axis=-2), axis=-1)
    length = np.sum(segments, axis=-1)
    chord_vector = x[..., -1, :] - x[..., 0, :]
    chord_length = np.linalg.norm(chord_vector, axis=-1)
    direction = chord_vector / np.maximum(chord_length, 1e-300)[..., None]
    relative = x - x[..., :1, :]
    along = np.sum(relative * direction[..., None, :], axis=-1)
    off = relative - along[..., None] * direction[..., None, :]
    distance = np.linalg.norm(off, axis=-1)
    return chord_length / length, np.mean(distance, axis=-1) / length


def sideways(root: np.ndarray, tip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Root and tip horizontal positions (F, T, 2) as signals (F, T) along each root's principal
    direction of motion, each minus its mean."""
    root = root - root.mean(axis=0)
    tip = tip - tip.mean(axis=0)
    covariance = np.einsum("fti,ftj->tij", root, root)
    _, vectors = np.linalg.eigh(covariance)
    direction = vectors[..., -1]  # (T, 2): the largest eigenvalue's
    return np.einsum("fti,ti->ft", root, direction), np.einsum("fti,ti->ft", tip, direction)


def root_tip_lag(root: np.ndarray, tip: np.ndarray, dt: float) -> tuple[float, float, float]:
    """How far ``tip`` (F, T) follows ``root`` (F, T), both sampled every ``dt``: at the root's
    dominant frequency f (the peak of its power spectrum, summed over the tentacles), the
    tip's phase behind the root's, as a delay in [0, 1/f) s. Returns the delay, the period 1/f
    and the coherence of the two at f, in [0, 1] (1: the tip follows one fixed delay)."""
    frames = root.shape[0]
    if frames < 4 or dt <= 0.0:
        return 0.0, 0.0, 0.0
    r = np.fft.rfft(root - root.mean(axis=0), axis=0)
    t = np.fft.rfft(tip - tip.mean(axis=0), axis=0)
    power = np.sum(np.abs(r) ** 2, axis=1)
    k = int(np.argmax(power[1:])) + 1
    cross = np.sum(t[k] * np.conj(r[k]))
    scale = np.sqrt(np.sum(np.abs(r[k]) ** 2) * np.sum(np.abs(t[k]) ** 2))
    if scale <= 0.0:
        return 0.0, frames * dt / k, 0.0
    period = frames * dt / k
    phase = float(np.mod(-np.angle(cross), 2.0 * np.pi))
    return phase / (2.0 * np.pi) * period, period, float(abs(cross) / scale)


def _measured(
    result: Result, groups: list[int], start: float | None
) -> tuple[np.ndarray, int, list[np.ndarray], np.ndarray]:
    """The frame times, the first frame analysed, and the chains of ``groups`` from it on, one
    (F, Tg, Pg, 3) array per group trimmed to its own particles; the rim (F, T, 3) from it on."""
    times = result.time
    first = int(np.searchsorted(times, times[-1] / 2 if start is None else start))
    first = min(first, max(0, len(times) - 2))
    frames = slice(first, None)
    chains = [result.group_positions(g, frames) for g in groups]
    return times, first, chains, result.read(fields.BELL_RIM, frames)


def _motion(times: np.ndarray, first: int, chains: list[np.ndarray], rim: np.ndarray) -> Motion:
    """:class:`Motion` of tentacles ``chains`` (one (F, Tg, Pg, 3) array per group, each of its
    own particle count) whose base points are ``rim`` (F, T', 3), T' the tentacles of all
    ``chains`` in order."""
    measures = [chord_and_bend(x) for x in chains]  # (F, Tg) each
    chord = np.concatenate([c for c, _ in measures], axis=1)
    bend = np.concatenate([b for _, b in measures], axis=1)
    root = np.concatenate([x[:, :, 0, :2] for x in chains], axis=1)  # (F, T', 2)
    tip = np.concatenate([x[:, :, -1, :2] for x in chains], axis=1)
    if root.shape[1] >= 3:
        centre = rim.mean(axis=1)[:, None, :2]  # the roots' centroid follows the bell's drift
        root, tip = root - centre, tip - centre
    dt = float(times[1] - times[0]) if len(times) > 1 else 0.0
    lag, period, coherence = root_tip_lag(*sideways(root, tip), dt)
    return Motion(
        start=float(times[first]),
        end=float(times[-1]),
        chord=float(chord.mean()),
        bend=float(bend.mean()),
        bend_peak=float(bend.mean(axis=1).max()),
        lag=lag,
        period=period,
        coherence=coherence,
    )


def tentacle_motion(
    result: Result, start: float | None = None, group: str | int | None = None
) -> Motion:
    """The tentacles' :class:`Motion` from ``start`` (s; default half the run) to the end: of
    ``group``'s tentacles (a name or an index into ``result.tentacle_groups``), or of every
    tentacle of every group (``None``), each chain its own particles (never the NaN rows that
    pad a shorter group's)."""
    groups = (
        [result.group_number(group)]
        if group is not None
        else [g for g in range(len(result.tentacle_groups)) if result.group_tentacles(g).size]
    )
    numbers = np.concatenate([result.group_tentacles(g) for g in groups])
    times, first, chains, rim = _measured(result, groups, start)
    return _motion(times, first, chains, rim[:, numbers])


def motion_by_group(result: Result, start: float | None = None) -> dict[str, Motion]:
    """Each group's :class:`Motion` (:func:`tentacle_motion` of that group), by group name, in
    the result's order; groups without tentacles are left out."""
    return {
        name: tentacle_motion(result, start, name)
        for k, name in enumerate(result.tentacle_groups)
        if result.group_tentacles(k).size
    }
