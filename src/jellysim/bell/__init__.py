"""Bell models: what drives the tentacle roots (paper §4.2), chosen by name.

A bell model is a :class:`RootDriver`: it places the tentacle roots on the margin and gives,
at any time, their positions, C1-continuous velocities and clamp directions, the bell's own
velocity and axis (the flow is relative to the bell), and the margin polyline.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from jellysim.config.schema import Scene


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


BELL_MODELS: dict[str, Callable[[Scene], RootDriver]] = {}


def register(name: str) -> Callable[[Callable[[Scene], RootDriver]], Callable[[Scene], RootDriver]]:
    def decorate(factory: Callable[[Scene], RootDriver]) -> Callable[[Scene], RootDriver]:
        BELL_MODELS[name] = factory
        return factory

    return decorate


def make_root_driver(scene: Scene) -> RootDriver:
    return BELL_MODELS[scene.bell.model](scene)


from jellysim.bell import forced  # noqa: E402,F401  (registers "none")
