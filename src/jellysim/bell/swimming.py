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
