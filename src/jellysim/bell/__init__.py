"""Bell models: what drives the tentacle roots (paper §4.2), chosen by name.

A bell model is a :class:`RootDriver`: it places the tentacle roots on the margin and gives,
at any time, their positions, C1-continuous velocities and clamp directions, the bell's own
velocity and axis (the flow is relative to the bell), and the margin polyline. A bell with a body
adds its own datasets to the result (its surface mesh, say) through ``frame_datasets``,
``frame_values`` and ``static_datasets``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple, Protocol

import numpy as np

from jellysim.config.schema import Scene
from jellysim.io.result import Dataset


class Forcing(NamedTuple):
    """How hard a bell drives the roots, for the choice of the substep."""

    speed: float  # m/s: the largest root speed relative to the bell's mean motion
    acceleration: float  # m/s2: the largest root acceleration
    period: float  # s: the period of an equivalent sine forcing (0: no forcing)


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

    def frame_datasets(self) -> list[Dataset]:
        """Per-frame datasets of the bell's body beyond the margin and the roots."""
        return []

    def frame_values(self, time: float) -> dict[str, np.ndarray]:
        """The values of :meth:`frame_datasets` at ``time``."""
        return {}

    def static_datasets(self) -> dict[str, tuple[np.ndarray, str]]:
        """Datasets written once (path: (array, units)), such as a fixed mesh topology."""
        return {}

    def links(self) -> dict[str, str]:
        """Dataset paths that are the same data as another (path: target), stored as links."""
        return {}


BELL_MODELS: dict[str, Callable[[Scene], RootDriver]] = {}


def register(name: str) -> Callable[[Callable[[Scene], RootDriver]], Callable[[Scene], RootDriver]]:
    def decorate(factory: Callable[[Scene], RootDriver]) -> Callable[[Scene], RootDriver]:
        BELL_MODELS[name] = factory
        return factory

    return decorate


def make_root_driver(scene: Scene) -> RootDriver:
    return BELL_MODELS[scene.bell.model](scene)


from jellysim.bell import forced, kinematic  # noqa: E402,F401  (register their models)
