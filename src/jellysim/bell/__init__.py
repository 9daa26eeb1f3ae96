"""Bell models chosen by name: the bells that drive the tentacle roots by a law of their own.

``bell.model = "none"`` (:mod:`.forced`, the paper's forced base point) and ``"kinematic"``
(:mod:`.kinematic`, the animated Brown Jelly bell) are :class:`BellModel` s: root drivers
(:class:`jellysim.tentacle.roots.RootDriver`) that also add their body's datasets to the result.
The mass-spring bell (:mod:`.soft`, :mod:`.skin`) is a body simulated in the water; what drives
its tentacles is the margin recorded from that simulation (:mod:`jellysim.coupling.margin`), so it
is not in this registry.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from jellysim.config.schema import Scene
from jellysim.fields import Dataset
from jellysim.tentacle.roots import RootDriver


class BellModel(RootDriver, Protocol):
    """A root driver with a body: per-frame and static datasets for the result."""

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

    def shell(self) -> tuple[Callable[[float], np.ndarray], np.ndarray] | None:
        """The body's closed surface, which the tentacles are kept out of
        (``bell.tentacle_contact``): its vertices (V, 3) m at a time (s) and its faces (F, 3);
        None for a model without a body."""
        return None


BELL_MODELS: dict[str, Callable[[Scene], BellModel]] = {}


def register(name: str) -> Callable[[Callable[[Scene], BellModel]], Callable[[Scene], BellModel]]:
    def decorate(factory: Callable[[Scene], BellModel]) -> Callable[[Scene], BellModel]:
        BELL_MODELS[name] = factory
        return factory

    return decorate


def make_root_driver(scene: Scene) -> BellModel:
    """The bell model of ``scene`` (``bell.model`` "none" or "kinematic")."""
    if scene.bell.model not in BELL_MODELS:
        raise ValueError(
            f"bell.model = {scene.bell.model!r} drives its roots from the simulated bell: "
            "build jellysim.Simulation(scene)"
        )
    return BELL_MODELS[scene.bell.model](scene)


from jellysim.bell import forced, kinematic  # noqa: E402,F401  (register their models)
