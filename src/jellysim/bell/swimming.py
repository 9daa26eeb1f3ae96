"""How a soft bell swims: per-pulse rise, contraction and the lag between them (paper Fig. 11).

The bell's height is the mean z of its particles (``bell/centre``), its contraction ratio
``1 - r / r_rest`` of the margin polyline's mean radius (``bell/contraction``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class SwimCycle(NamedTuple):
    """One whole pulse ``[start, start + period)``: the rise of the bell's mean height (m), the
    times (s) of peak contraction and of peak upward speed, and their lag (s, speed after
    contraction is positive), the peak contraction ratio."""

    start: float
    rise: float
    peak_contraction_time: float
    peak_speed_time: float
    lag: float
    peak_contraction: float


def swim_cycles(
    time: np.ndarray, height: np.ndarray, contraction: np.ndarray, period: float
) -> list[SwimCycle]:
    """The whole pulses in a record sampled at ``time`` (F,) s: ``height`` (F,) m and
    ``contraction`` (F,). The upward speed is the central difference of the height."""
    speed = np.gradient(height, time)
    cycles = []
    for k in range(int(np.floor((time[-1] + 1e-9) / period))):
        start, stop = k * period, (k + 1) * period
        inside = (time >= start - 1e-9) & (time <= stop + 1e-9)
        index = np.flatnonzero(inside)
        if len(index) < 3:
            continue
        first, last = index[0], index[-1]
        contraction_peak = index[np.argmax(contraction[index])]
        speed_peak = index[np.argmax(speed[index])]
        cycles.append(
            SwimCycle(
                start,
                float(height[last] - height[first]),
                float(time[contraction_peak]),
                float(time[speed_peak]),
                float(time[speed_peak] - time[contraction_peak]),
                float(contraction[contraction_peak]),
            )
        )
    return cycles


class PhaseLag(NamedTuple):
    """How long after the contraction the upward speed follows (s, in [0, period)), and the
    correlation of the two at that lag."""

    lag: float
    correlation: float


def phase_lag(
    time: np.ndarray, height: np.ndarray, contraction: np.ndarray, period: float
) -> PhaseLag | None:
    """The lag (s) that best aligns the upward speed with the contraction over the whole pulses
    after the first (a start-up transient), both detrended; None if the record holds no whole
    pulse after the first or its frames do not divide the period.

    The per-pulse peaks of :func:`swim_cycles` are fragile when the bell does not re-open fully
    between pulses; the correlation uses every sample of a pulse."""
    if len(time) < 3:
        return None
    step = float(time[1] - time[0])
    per_period = round(period / step)
    if per_period < 2 or abs(per_period * step - period) > 1e-6 * period:
        return None
    speed = np.gradient(height, time)
    first = per_period  # the sample at t = period
    whole = (len(time) - 1 - first) // per_period * per_period
    if whole < per_period:
        return None
    window = slice(first, first + whole)
    c = _detrended(contraction[window])
    v = _detrended(speed[window])
    norm = float(np.sqrt(np.dot(c, c) * np.dot(v, v)))
    if norm == 0.0:
        return None
    # Circular over whole pulses: the detrended records are nearly periodic.
    scores = np.array([np.dot(c, np.roll(v, -shift)) / norm for shift in range(per_period)])
    best = int(np.argmax(scores))
    return PhaseLag(best * step, float(scores[best]))


def _detrended(values: np.ndarray) -> np.ndarray:
    k = np.arange(len(values), dtype=np.float64)
    return values - np.polyval(np.polyfit(k, values, 1), k)
