"""The frame loop: a scene in, ``result.h5`` out (DESIGN §1).

:class:`Simulation` holds the parameters (built once) apart from the state (mutated in place);
``step_frame`` advances every tentacle through one frame's substeps in one compiled call.
:func:`run` adds the result store, checkpoints, resume, the watchdog and progress.
"""

from __future__ import annotations

import logging
import math
import os
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from jellysim.bell import RootDriver, make_root_driver
from jellysim.config import Scene, load_scene, scene_to_toml
from jellysim.errors import InputError, SimulationUnstable
from jellysim.io.checkpoint import (
    load_checkpoint,
    remove_checkpoint,
    save_checkpoint,
    scene_mismatch,
)
from jellysim.io.folders import output_folder
from jellysim.io.result import RESULT_FILE, Result, ResultWriter, frame_datasets, read_frames
from jellysim.progress import progress
from jellysim.tentacle import kernels
from jellysim.tentacle.flow import flow_noise_for, water_velocity
from jellysim.tentacle.kernels import advance_frame
from jellysim.tentacle.model import chain_model_for, characteristic_speed, medium_for, plan_substeps

log = logging.getLogger(__name__)

SCENE_FILE = "scene.toml"
# Watchdog: a chain whose RMS speed exceeds this multiple of the scene's speed scale has run away.
RUNAWAY_SPEED_FACTOR = 100.0

Observer = Callable[["Simulation"], None]


class Simulation:
    """One scene's tentacles and their driver.

    State (mutated in place, never rebound): ``positions``, ``velocities`` (T, P, 3) in m, m/s;
    ``frame`` the index of the frame the state belongs to (time ``frame / fps``).
    """

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.driver: RootDriver = make_root_driver(scene)
        self.model = chain_model_for(scene)
        self.medium = medium_for(scene)
        self.noise = flow_noise_for(scene)
        self.plan = plan_substeps(scene)
        self.frame_dt = 1.0 / scene.fps
        self.observers: list[Observer] = []
        t = scene.tentacles
        self.positions = np.empty((t.count, t.particles, 3))
        self.velocities = np.empty((t.count, t.particles, 3))
        self.diagnostics = np.zeros((t.count, 3))
        self.frame = 0
        self.reset()
        self.speed_limit = RUNAWAY_SPEED_FACTOR * self._speed_scale()

    def _speed_scale(self) -> float:
        """A speed the tentacles should never much exceed (m/s)."""
        s = self.scene
        length = (s.tentacles.particles - 1) * s.tentacles.spacing
        g = float(np.linalg.norm(s.water.gravity))
        contrast = abs(s.tentacle_density - s.water.density) / s.tentacle_density
        return characteristic_speed(s) + math.sqrt(g * length * contrast) + 0.1

    def reset(self) -> None:
        """Frame 0: every tentacle straight from its root along its clamp direction, moving
        rigidly with its root (no impulsive start)."""
        roots, root_velocities, directions = self.driver.roots(np.zeros(1))
        self._rim = (0, roots[0], root_velocities[0])  # (frame, rim, rim velocity)
        offsets = np.arange(self.scene.tentacles.particles) * self.scene.tentacles.spacing
        self.positions[:] = (
            roots[0][:, None, :] + offsets[None, :, None] * directions[0][:, None, :]
        )
        self.velocities[:] = root_velocities[0][:, None, :]
        self.frame = 0

    @property
    def time(self) -> float:
        return self.frame * self.frame_dt

    def substep_times(self, frame: int) -> np.ndarray:
        """End times (s) of the substeps that lead from ``frame`` to ``frame + 1``."""
        n = self.plan.substeps
        return (frame * n + np.arange(1, n + 1)) * (self.frame_dt / n)

    def prepare(self) -> None:
        """Compile the kernels (or load them from Numba's cache) on a throw-away copy of the
        state, so that the first frame's timing, and the progress bar's ETA, are honest."""
        times = self.substep_times(self.frame)[:1]
        roots, root_velocities, directions = self.driver.roots(times)
        kernels.advance_frame(
            self.positions.copy(),
            self.velocities.copy(),
            roots,
            root_velocities,
            directions,
            np.zeros_like(roots),
            self.model,
            self.medium,
            self.plan.dt,
            self.diagnostics.copy(),
        )

    def step_frame(self) -> None:
        """Advance the state by one frame; raise SimulationUnstable if it diverged."""
        times = self.substep_times(self.frame)
        roots, root_velocities, directions = self.driver.roots(times)
        flow = water_velocity(
            self.scene.flow.speed,
            self.driver.axis(times),
            self.driver.bell_velocity(times),
            self.noise.sample(times),
        )
        advance_frame(
            self.positions,
            self.velocities,
            roots,
            root_velocities,
            directions,
            flow,
            self.model,
            self.medium,
            self.plan.dt,
            self.diagnostics,
        )
        self.frame += 1
        self._rim = (self.frame, roots[-1], root_velocities[-1])  # what drove the roots last
        for observer in self.observers:
            observer(self)
        self._watchdog(times)

    def _watchdog(self, times: np.ndarray) -> None:
        failed = self.diagnostics[:, 2]
        if np.any(failed >= 0):
            # The chain that failed first (lowest substep), the lowest index among equals.
            chain = int(np.argmin(np.where(failed >= 0, failed, np.inf)))
            when = float(times[int(failed[chain])])
            raise SimulationUnstable(
                f"unstable at t = {when:.6g} s in tentacle {chain}: the state became non-finite "
                "or the length constraint could not be met; lower solver.dt_safety "
                "or check the scene's forces",
                time=when,
                tentacle=chain,
            )
        rms = np.sqrt(np.mean(np.sum(self.velocities**2, axis=2), axis=1))
        finite = np.isfinite(rms) & np.all(np.isfinite(self.positions), axis=(1, 2))
        if not np.all(finite):
            chain = int(np.argmax(~finite))
            raise SimulationUnstable(
                f"unstable at t = {self.time:.6g} s in tentacle {chain}: the state became "
                "non-finite; lower solver.dt_safety or check the scene's forces",
                time=self.time,
                tentacle=chain,
            )
        if np.any(rms > self.speed_limit):
            chain = int(np.argmax(rms > self.speed_limit))
            raise SimulationUnstable(
                f"runaway energy at t = {self.time:.6g} s in tentacle {chain}: RMS speed "
                f"{rms[chain]:.3g} m/s exceeds {self.speed_limit:.3g} m/s; lower solver.dt_safety "
                "or check the scene's forces",
                time=self.time,
                tentacle=chain,
            )

    def frame_values(self) -> dict[str, Any]:
        """The current frame as the result store's datasets."""
        frame, rim, rim_velocity = self._rim
        if frame != self.frame:  # the state was set from outside (a resume, a script)
            roots, root_velocities, _ = self.driver.roots(np.array([self.time]))
            rim, rim_velocity = roots[0], root_velocities[0]
        return {
            "time": self.time,
            "tentacles/position": self.positions,
            "tentacles/velocity": self.velocities,
            "tentacles/constraint_error": float(self.diagnostics[:, 0].max(initial=0.0)),
            "tentacles/projection_iterations": int(self.diagnostics[:, 1].max(initial=0.0)),
            "bell/rim": rim,
            "bell/rim_velocity": rim_velocity,
            "bell/margin": self.driver.margin(self.time),
            **self.driver.frame_values(self.time),
        }

    def describe(self) -> str:
        t = self.scene.tentacles
        return f"{t.count} tentacles x {t.particles} particles, {self.plan.describe()}"

    def checkpoint_state(self) -> dict[str, np.ndarray]:
        return {"positions": self.positions, "velocities": self.velocities}

    def restore(self, frame: int, state: dict[str, np.ndarray]) -> None:
        """Continue from a checkpoint's state after ``frame``."""
        self.positions[:] = state["positions"]
        self.velocities[:] = state["velocities"]
        self.frame = frame

    def finish(self) -> None:
        """Nothing to report beyond the result."""

    def datasets(self) -> list[Any]:
        t = self.scene.tentacles
        return [
            *frame_datasets(t.count, t.particles, self.driver.margin(0.0).shape[0]),
            *self.driver.frame_datasets(),
        ]

    def writer(
        self, path: Path, scene_toml: str, initial: dict[str, np.ndarray] | None = None
    ) -> ResultWriter:
        """A result store for this simulation's datasets, the bell's included."""
        return ResultWriter(
            path,
            self.datasets(),
            self.attributes(scene_toml),
            initial,
            static=self.driver.static_datasets(),
            links=self.driver.links(),
        )

    def attributes(self, scene_toml: str) -> dict[str, Any]:
        return {
            **result_attributes(self.scene, scene_toml),
            "tentacle_dt": self.plan.dt,
            "tentacle_substeps": self.plan.substeps,
            "bell_model": self.scene.bell.model,
        }


def result_attributes(scene: Scene, scene_toml: str) -> dict[str, Any]:
    """The root attributes every result carries (DESIGN §3)."""
    from jellysim._version import __version__

    return {
        "scene": scene_toml,
        "version": __version__,
        "seed": scene.seed,
        "frames_expected": scene.frame_count,
        "fps": scene.fps,
    }


def make_simulation(scene: Scene) -> Any:
    """The frame loop for a scene: tentacles driven by a bell, the soft bell in its fluid, or a
    fluid-only MPS scene."""
    if scene.bell.model == "mass-spring":
        from jellysim.simulation.soft import SoftBellSimulation

        return SoftBellSimulation(scene)
    if scene.fluid.model == "mps":
        from jellysim.simulation.fluid import FluidSimulation

        return FluidSimulation(scene)
    return Simulation(scene)


def default_out(scene: Scene) -> Path:
    return Path("out") / scene.name


def _write_text_atomic(path: Path, text: str) -> None:
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(text, encoding="utf-8")
    os.replace(temporary, path)


def run(
    scene: Scene | str | os.PathLike[str] | Mapping[str, Any],
    out: str | os.PathLike[str] | None = None,
    *,
    overrides: Mapping[str, Any] | None = None,
    force: bool = False,
    resume: bool = False,
    quiet: bool = True,
    observers: list[Observer] | None = None,
) -> Result:
    """Run a scene to ``out/result.h5`` (default ``out/<name>``) and return the open result.

    ``force`` replaces an existing result; ``resume`` continues it from its last checkpoint.
    ``quiet=False`` shows a progress bar with ETA on runs longer than two seconds.
    """
    if not isinstance(scene, Scene) or overrides:
        scene = load_scene(scene if not isinstance(scene, os.PathLike) else str(scene), overrides)
    folder = Path(out) if out is not None else default_out(scene)
    result_path = folder / RESULT_FILE
    scene_toml = scene_to_toml(scene)
    if force and resume:
        raise InputError("--force and --resume exclude each other")
    if folder.exists() and not folder.is_dir():
        raise InputError(f"--out {folder}: exists and is not a folder")
    if result_path.exists() and not (force or resume):
        raise InputError(f"{result_path} exists; --force replaces it, --resume continues it")
    if resume and not result_path.exists():
        raise InputError(f"nothing to resume in '{folder}': no {RESULT_FILE}")

    simulation = make_simulation(scene)
    for observer in observers or []:
        simulation.observers.append(observer)
    datasets = simulation.datasets()
    if resume:
        with Result(folder) as existing:
            same_scene = existing.scene_text == scene_toml
            complete = existing.complete
        if not same_scene:
            raise scene_mismatch(folder)
        if complete:
            log.info("%s is complete; nothing to resume", result_path)
            return Result(folder)
        frame, state = load_checkpoint(folder, scene_toml)
        simulation.restore(frame, state)
        kept = read_frames(result_path, datasets, frame + 1)
        writer = simulation.writer(result_path, scene_toml, kept)
    else:
        output_folder(folder)
        remove_checkpoint(folder)
        _write_text_atomic(folder / SCENE_FILE, scene_toml)
        writer = simulation.writer(result_path, scene_toml)
        writer.append(simulation.frame_values())

    log.info(
        "%s: %s, %d frames -> %s", scene.name, simulation.describe(), scene.frame_count, result_path
    )
    every = scene.solver.checkpoint_every
    try:
        start = time.perf_counter()
        simulation.prepare()
        log.info("compiled kernels ready in %.1f s", time.perf_counter() - start)
        total, done = scene.frame_count - 1, simulation.frame
        with progress(total, done, quiet, "simulating", delay=2.0) as bar:
            while simulation.frame < scene.frame_count - 1:
                simulation.step_frame()
                writer.append(simulation.frame_values())
                if simulation.frame % every == 0:
                    writer.flush()  # the checkpoint's frame must be on disk first
                    save_checkpoint(
                        folder, simulation.frame, scene_toml, simulation.checkpoint_state()
                    )
                bar.update(1)
    finally:
        writer.close()
    simulation.finish()
    remove_checkpoint(folder)
    return Result(folder)
