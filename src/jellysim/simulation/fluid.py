"""A fluid-only scene (``fluid.model = "mps"``): the MPS fluid in its tank, frame by frame.

Within a frame the fluid takes equal steps of at most the stable dt the solver chooses (CFL,
acceleration and viscous limits), landing on the frame time (:func:`jellysim.fluid.frames.
advance_to`). The helpers here describe the fluid's datasets for this loop and the soft bell's.
"""

from __future__ import annotations

import dataclasses
import logging
from typing import Any

import numpy as np

from jellysim import fields
from jellysim.config import Scene
from jellysim.fields import Dataset
from jellysim.fluid.frames import FrameStats, advance_to, compile_on_copy
from jellysim.fluid.geometry import FLUID
from jellysim.fluid.mps import MPSSolver
from jellysim.fluid.probes import HeightProbes, PressureProbes
from jellysim.fluid.setup import fluid_particles, make_solver, mps_parameters, tank_corner
from jellysim.simulation.loop import Simulation, register_loop

log = logging.getLogger(__name__)


def fluid_datasets(particles: int, dim: int, dtype: Any = np.float64) -> list[Dataset]:
    """The fluid's per-frame datasets for ``particles`` of ``dim`` dimensions, floats stored as
    ``dtype``, and the pressure solver's."""
    return [
        fields.FLUID_POSITION.dataset(dtype, N=particles, D=dim),
        fields.FLUID_VELOCITY.dataset(dtype, N=particles, D=dim),
        fields.FLUID_PRESSURE.dataset(dtype, N=particles),
        fields.FLUID_NUMBER_DENSITY.dataset(dtype, N=particles),
        fields.FLUID_ALIVE.dataset(N=particles),
        fields.SOLVER_ITERATIONS.dataset(),
        fields.SOLVER_RESIDUAL.dataset(),
        fields.SOLVER_STEPS.dataset(),
    ]


def fluid_values(solver: MPSSolver, rows: Any, stats: FrameStats) -> dict[str, Any]:
    """The values of :func:`fluid_datasets`: the solver's ``rows`` (an index or a slice)."""
    return {
        fields.FLUID_POSITION.path: solver.position[rows],
        fields.FLUID_VELOCITY.path: solver.velocity[rows],
        fields.FLUID_PRESSURE.path: solver.pressure[rows],
        fields.FLUID_NUMBER_DENSITY.path: solver.number_density[rows],
        fields.FLUID_ALIVE.path: solver.alive[rows],
        fields.SOLVER_ITERATIONS.path: stats.iterations,
        fields.SOLVER_RESIDUAL.path: stats.residual,
        fields.SOLVER_STEPS.path: stats.steps,
    }


def report(solver: MPSSolver, stats: FrameStats) -> None:
    """Log what the run did: particles that left the domain, time per phase."""
    dead = int(np.sum(~solver.alive))
    if dead:
        log.warning("%d particles left the domain (fluid/alive is False for them)", dead)
    if stats.seconds:
        total = sum(stats.seconds.values())
        parts = ", ".join(f"{k} {v:.1f} s ({v / total:.0%})" for k, v in stats.seconds.items())
        log.info("fluid time per phase: %s; %.1f s in all", parts, total)


class Probes:
    """A scene's height and pressure probes (:mod:`jellysim.fluid.probes`) on its solver, and
    their datasets ``probes/height`` (F, H) m and ``probes/pressure`` (F, K) Pa, each with the
    probes' ``names``. The pressure probes are read each step through the solver's
    ``pressure_gauge`` (on the GPU, K numbers a step come to the host); the heights once a
    frame, from the frame's host copies of the state."""

    def __init__(self, scene: Scene, solver: MPSSolver) -> None:
        p = scene.probes
        self.solver = solver
        self.height_names = [name for name, _ in p.height]
        self.pressure_names = [name for name, _ in p.pressure]
        dim, l0 = solver.params.dim, solver.params.l0
        self.height = HeightProbes(
            np.array([place for _, place in p.height]), l0, dim, scene.fluid.lattice
        )
        self.pressure = PressureProbes(
            np.array([point for _, point in p.pressure]),
            solver.position,
            solver.kind,
            l0,
            tank_corner(scene),
            np.array(scene.fluid.obstacles).reshape(-1, 2 * dim),
        )
        self.gauge = solver.pressure_gauge(self.pressure.rows, self.pressure.weights)
        self.end_frame()  # frame 0 (or a restored frame): the pressure now

    def after_step(self, dt: float) -> None:
        self.pressure.add_step(self.gauge(), dt)

    def end_frame(self) -> None:
        """Close the frame's pressure means (called once a frame, after its steps)."""
        self.frame_pressure = self.pressure.frame_mean(self.gauge)

    def frame_values(self) -> dict[str, np.ndarray]:
        s = self.solver
        values = {}
        if self.height_names:
            values[fields.PROBE_HEIGHT.path] = self.height.measure(s.position, s.kind, s.alive)
        if self.pressure_names:
            values[fields.PROBE_PRESSURE.path] = self.frame_pressure.copy()
        return values

    def datasets(self) -> list[Dataset]:
        out = []
        for field, names, axis in (
            (fields.PROBE_HEIGHT, self.height_names, "H"),
            (fields.PROBE_PRESSURE, self.pressure_names, "K"),
        ):
            if names:
                spec = field.dataset(**{axis: len(names)})
                out.append(dataclasses.replace(spec, attributes=(("names", names),)))
        return out


@register_loop("fluid")
class FluidSimulation(Simulation):
    """One fluid-only scene: the solver (its state mutated in place) and the frame counter."""

    def __init__(self, scene: Scene) -> None:
        super().__init__(scene)
        positions, kinds, self.geometry = fluid_particles(scene)
        self.solver: Any = make_solver(mps_parameters(scene), positions, kinds, scene.fluid.device)
        self.stats = FrameStats()
        self.probes = (
            Probes(scene, self.solver) if scene.probes.height or scene.probes.pressure else None
        )

    def describe(self) -> str:
        fluid = int(np.sum(self.solver.kind == FLUID))
        gpu = self.scene.fluid.device == "cuda"
        where = ", on the GPU (Jacobi-preconditioned CG)" if gpu else ""
        return (
            f"MPS {self.scene.fluid.dimensions}-D, {fluid} fluid and "
            f"{len(self.solver.kind) - fluid} wall particles, l0 = {self.solver.params.l0:g} m"
            f"{where}"
        )

    def prepare(self) -> None:
        if self.scene.fluid.device == "cpu":  # the GPU's kernels compile in the first step
            compile_on_copy(self.solver)

    def step_frame(self) -> None:
        """Advance the fluid to the next frame time; raise SimulationUnstable if it diverged."""
        advance_to(
            self.solver,
            (self.frame + 1) * self.frame_dt,
            self.frame_dt,
            self.stats,
            after_step=None if self.probes is None else self.probes.after_step,
        )
        if self.probes is not None:
            self.probes.end_frame()
        self.frame += 1
        self.notify()

    def frame_values(self) -> dict[str, Any]:
        values = {fields.TIME.path: self.time, **fluid_values(self.solver, slice(None), self.stats)}
        if self.probes is not None:
            values.update(self.probes.frame_values())
        return values

    def datasets(self) -> list[Dataset]:
        n, dim = self.solver.position.shape
        probes = [] if self.probes is None else self.probes.datasets()
        return [fields.TIME.dataset(), *fluid_datasets(n, dim), *probes]

    def static_datasets(self) -> dict[str, tuple[np.ndarray, str]]:
        return {fields.FLUID_KIND.path: (self.solver.kind, fields.FLUID_KIND.units)}

    def attributes(self, scene_toml: str) -> dict[str, Any]:
        return {
            **super().attributes(scene_toml),
            "particle_spacing": self.solver.params.l0,
            "fluid_particles": int(np.sum(self.solver.kind == FLUID)),
            **self.geometry,
        }

    def checkpoint_state(self) -> dict[str, np.ndarray]:
        return {**self.solver.state_arrays(), "last": self.stats.as_array()}

    def restore(self, frame: int, state: dict[str, np.ndarray]) -> None:
        state = dict(state)
        self.stats.restore(state.pop("last"))
        self.solver.restore(state)
        self.frame = frame
        if self.probes is not None:
            self.probes.end_frame()  # the restored frame's pressure, and no steps half-counted

    def finish(self) -> None:
        report(self.solver, self.stats)
