"""The frame-loop contract every scene's simulation keeps, and the registry that picks the loop.

A loop is built from a scene, compiles its kernels (:meth:`FrameLoop.prepare`), advances one frame
at a time (:meth:`FrameLoop.step_frame`), holds its state in arrays mutated in place
(:meth:`FrameLoop.checkpoint_state`, :meth:`FrameLoop.restore`), declares the datasets it writes
before the first frame (:meth:`FrameLoop.datasets`, :meth:`FrameLoop.static_datasets`,
:meth:`FrameLoop.links`) and gives their values each frame (:meth:`FrameLoop.frame_values`).
:func:`jellysim.simulation.run.run` drives any loop the same way: result store, checkpoints,
resume, progress.

``Simulation(scene)`` is the one public constructor: it builds the loop the registry names for the
scene (``"tentacles"``, ``"fluid"`` or ``"soft-bell"``, :func:`loop_name`), an instance of the
registered subclass of :class:`Simulation`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar, Protocol

import numpy as np

from jellysim._version import __version__
from jellysim.config import Scene
from jellysim.fields import Dataset
from jellysim.io.result import ResultWriter

Observer = Callable[[Any], None]


class FrameLoop(Protocol):
    """What :func:`jellysim.run` needs of a scene's simulation.

    State: ``frame``, the index of the frame the state belongs to (time ``frame / fps``); the
    arrays of :meth:`checkpoint_state`, mutated in place. ``observers`` are called with the loop
    after every frame.
    """

    scene: Scene
    frame: int
    observers: list[Observer]

    @property
    def time(self) -> float:
        """The state's time (s)."""
        ...

    def describe(self) -> str:
        """One line: what is simulated, and how finely."""
        ...

    def prepare(self) -> None:
        """Compile the kernels (or load them from Numba's cache) without touching the state."""
        ...

    def step_frame(self) -> None:
        """Advance the state by one frame; raise SimulationUnstable if it diverged."""
        ...

    def checkpoint_state(self) -> dict[str, np.ndarray]:
        """Every array the next frames depend on (a resume from them is bit for bit)."""
        ...

    def restore(self, frame: int, state: dict[str, np.ndarray]) -> None:
        """Continue after ``frame`` from :meth:`checkpoint_state` arrays."""
        ...

    def datasets(self) -> list[Dataset]:
        """The per-frame datasets this loop writes, declared before the first frame."""
        ...

    def static_datasets(self) -> dict[str, tuple[np.ndarray, str]]:
        """Datasets written once (path: (array, units))."""
        ...

    def links(self) -> dict[str, str]:
        """Per-frame datasets stored again under another path (path: target)."""
        ...

    def attributes(self, scene_toml: str) -> dict[str, Any]:
        """The result's root attributes."""
        ...

    def frame_values(self) -> dict[str, Any]:
        """The current frame's values of :meth:`datasets`, by path."""
        ...

    def finish(self) -> None:
        """Report what the run did beyond the result (logged)."""
        ...


LOOPS: dict[str, type[Simulation]] = {}


def register_loop(name: str) -> Callable[[type[Simulation]], type[Simulation]]:
    def decorate(loop: type[Simulation]) -> type[Simulation]:
        loop.loop = name
        LOOPS[name] = loop
        return loop

    return decorate


def loop_name(scene: Scene) -> str:
    """The loop a scene needs: the soft bell in its water (which drives the tentacles, if any),
    a fluid-only MPS scene, or tentacles driven by a bell model (the scene schema allows no other
    combination)."""
    if scene.bell.model == "mass-spring":
        return "soft-bell"
    if scene.fluid.model == "mps":
        return "fluid"
    return "tentacles"


def result_attributes(scene: Scene, scene_toml: str) -> dict[str, Any]:
    """The root attributes every result carries (DESIGN §3)."""
    return {
        "scene": scene_toml,
        "version": __version__,
        "seed": scene.seed,
        "frames_expected": scene.frame_count,
        "fps": scene.fps,
    }


def make_loop(scene: Scene) -> Simulation:
    """The loop for ``scene`` (what ``Simulation(scene)`` builds)."""
    return LOOPS[loop_name(scene)](scene)


class Simulation(ABC):
    """Any scene, frame by frame (:class:`FrameLoop`): ``Simulation(scene)`` builds the loop that
    :func:`loop_name` names for it, an instance of the subclass registered under that name,
    after refusing (InputError) a scene whose estimated memory exceeds what the machine has
    available (:func:`jellysim.simulation.estimate.check_costs`).

    Every loop has ``scene``, ``frame`` and ``time``, ``observers`` (called with the loop after
    each frame) and ``step_frame()``; :class:`FrameLoop` lists the rest.
    """

    loop: ClassVar[str] = ""

    def __new__(cls, scene: Scene, *args: Any, **kwargs: Any) -> Simulation:
        if cls is Simulation:
            # the public constructor refuses, before allocating, what the machine cannot hold
            from jellysim.simulation.estimate import check_costs  # it imports this module

            check_costs(scene)
            cls = LOOPS[loop_name(scene)]
        return super().__new__(cls)

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.frame_dt = 1.0 / scene.fps
        self.frame = 0
        self.observers: list[Observer] = []

    @property
    def time(self) -> float:
        return self.frame * self.frame_dt

    def notify(self) -> None:
        """Call the observers with this loop (after a frame)."""
        for observer in self.observers:
            observer(self)

    # What each loop defines (:class:`FrameLoop` documents them).

    @abstractmethod
    def describe(self) -> str: ...

    @abstractmethod
    def prepare(self) -> None: ...

    @abstractmethod
    def step_frame(self) -> None: ...

    @abstractmethod
    def checkpoint_state(self) -> dict[str, np.ndarray]: ...

    @abstractmethod
    def restore(self, frame: int, state: dict[str, np.ndarray]) -> None: ...

    @abstractmethod
    def datasets(self) -> list[Dataset]: ...

    @abstractmethod
    def frame_values(self) -> dict[str, Any]: ...

    @abstractmethod
    def finish(self) -> None: ...

    # What loops share, or override.

    def static_datasets(self) -> dict[str, tuple[np.ndarray, str]]:
        return {}

    def links(self) -> dict[str, str]:
        return {}

    def attributes(self, scene_toml: str) -> dict[str, Any]:
        return result_attributes(self.scene, scene_toml)

    def writer(
        self, path: Path, scene_toml: str, initial: dict[str, np.ndarray] | None = None
    ) -> ResultWriter:
        """A result store for this loop's datasets."""
        return ResultWriter(
            path,
            self.datasets(),
            self.attributes(scene_toml),
            initial,
            static=self.static_datasets(),
            links=self.links(),
        )
