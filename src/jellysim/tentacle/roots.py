"""What drives the tentacle roots (paper §4.1, §4.2.4): the protocol a root driver keeps.

The tentacles are handed a :class:`RootDriver` (a bell model, the forced base point, or the soft
bell's recorded margin); they never build one themselves. A driver gives, at any time, the roots'
positions, C1-continuous velocities and clamp directions, the bell's own velocity and axis (the
assumed flow is relative to the bell), the margin polyline, and the scales of its forcing, from
which the tentacles choose their substep.
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np


class Forcing(NamedTuple):
    """How hard a driver moves the roots, for the choice of the substep."""

    speed: float  # m/s: the largest root speed relative to the bell's mean motion
    acceleration: float  # m/s2: the largest root acceleration
    period: float  # s: the period of an equivalent sine forcing (0: no forcing)


NO_FORCING = Forcing(0.0, 0.0, 0.0)


class RootDriver(Protocol):
    """Prescribes the tentacle roots. Times are (S,) arrays in s."""

    def roots(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Root positions (m), velocities (m/s) and unit clamp directions, each (S, T, 3)."""
        ...

    def bell_velocity(self, times: np.ndarray) -> np.ndarray:
        """Velocity (m/s) of the bell's frame, (S, 3)."""
        ...

    def axis(self, times: np.ndarray) -> np.ndarray:
        """Unit bell axis (the swimming direction, +z at rest), (S, 3)."""
        ...

    def margin(self, time: float) -> np.ndarray:
        """The margin as a closed polyline, (R, 3) m; the roots lie on it."""
        ...

    def forcing(self) -> Forcing:
        """The scales of the root motion."""
        ...
