"""A fluid-only scene (``fluid.model = "mps"``): the MPS fluid in its tank, frame by frame.

The same frame-loop contract as :class:`jellysim.simulation.Simulation` (``step_frame``,
``frame_values``, ``datasets``, ``writer``, ``checkpoint_state``/``restore``), so that
:func:`jellysim.simulation.run` stores, checkpoints, resumes and watches it the same way.
Within a frame the fluid takes equal steps of at most the stable dt the solver chooses (CFL,
acceleration and viscous limits), landing on the frame time (:func:`jellysim.fluid.mps.substep`).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from jellysim.config import Scene
from jellysim.errors import SimulationUnstable
from jellysim.fluid.geometry import FLUID, filled_height, tank, water_block
from jellysim.fluid.mps import FluidDiverged, MPSParameters, MPSSolver, substep
from jellysim.io.result import Dataset, ResultWriter

log = logging.getLogger(__name__)


def fluid_particles(scene: Scene) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """The tank and its water: positions (N, D) m, kinds (N,) and the case geometry attributes
    of DESIGN §3 (left inner wall at x = 0, floor at 0 along the last axis). On the hexagonal
    and fcc lattices the height attribute is the height the water's rows or layers fill
    (:func:`filled_height`)."""
    f = scene.fluid
    dim, l0 = f.dimensions, f.spacing
    walls, kinds = tank(
        f.tank_width,
        f.tank_height,
        l0,
        dim=dim,
        inner_depth=f.tank_depth if dim == 3 else None,
        lattice=f.lattice,
    )
    width = f.water_width if f.geometry == "dam-break" else f.tank_width
    height = filled_height(f.water_height, l0, f.lattice)
    if dim == 2:
        water = water_block(0.0, width, 0.0, f.water_height, l0, lattice=f.lattice)
    else:
        water = water_block(
            0.0, width, 0.0, f.tank_depth, l0, 0.0, f.water_height, lattice=f.lattice
        )
    positions = np.concatenate([water, walls])
    all_kinds = np.concatenate([np.full(len(water), FLUID, dtype=np.int8), kinds])
    if f.geometry == "dam-break":
        attributes = {"column_width": width, "column_height": height}
    else:
        attributes = {"water_depth": height}
    return positions, all_kinds, attributes


def mps_parameters(scene: Scene) -> MPSParameters:
    f, w = scene.fluid, scene.water
    return MPSParameters(
        dim=f.dimensions,
        l0=f.spacing,
        density=w.density,
        kinematic_viscosity=w.viscosity / w.density,
        gravity=tuple(w.gravity[: f.dimensions]),
        source=f.source,
        surface=f.surface,
        gradient=f.gradient,
        surface_threshold=f.surface_threshold,
        collision_distance=f.collision_distance,
        surface_repulsion=f.surface_repulsion,
        lattice=f.lattice,
        solver=f.solver,
        coarse_cell=f.coarse_cell,
        neighbour_skin=f.neighbour_skin,
        tolerance=f.tolerance,
        courant=f.courant,
    )


class FluidSimulation:
    """One fluid-only scene: the solver (its state mutated in place) and the frame counter."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        positions, kinds, self.geometry = fluid_particles(scene)
        self.solver = MPSSolver(mps_parameters(scene), positions, kinds)
        self.frame_dt = 1.0 / scene.fps
        self.frame = 0
        self.observers: list[Any] = []
        self.last = {"iterations": 0, "residual": 0.0, "steps": 0}
        self.seconds: dict[str, float] = {}

    @property
    def time(self) -> float:
        return self.frame * self.frame_dt

    def describe(self) -> str:
        fluid = int(np.sum(self.solver.kind == FLUID))
        return (
            f"MPS {self.scene.fluid.dimensions}-D, {fluid} fluid and "
            f"{len(self.solver.kind) - fluid} wall particles, l0 = {self.scene.fluid.spacing:g} m"
        )

    def prepare(self) -> None:
        """Compile the kernels (or load them from the cache) on a throw-away copy."""
        probe = MPSSolver(self.solver.params, self.solver.position.copy(), self.solver.kind)
        probe.restore(self.solver.state_arrays())
        try:
            probe.step(min(probe.stable_dt(), 1e-6))
        except FluidDiverged:
            pass  # the first real step reports it, with its time; it compiles what is left

    def step_frame(self) -> None:
        """Advance the fluid to the next frame time; raise SimulationUnstable if it diverged."""
        end = (self.frame + 1) * self.frame_dt
        solver = self.solver
        iterations, residual, steps = 0, 0.0, 0
        while solver.time < end - 1e-12 * self.frame_dt:
            dt = substep(end - solver.time, solver.stable_dt())
            try:
                stats = solver.step(dt)
            except FluidDiverged as err:
                raise SimulationUnstable(
                    f"the fluid diverged at t = {err.time:.6g} s: the pressure solve reached "
                    f"{err.iterations} iterations with relative residual {err.residual:.3g}; "
                    "lower fluid.courant or refine fluid.spacing",
                    time=err.time,
                ) from None
            iterations, residual, steps = stats.iterations, stats.residual, steps + 1
            for phase, seconds in stats.seconds.items():
                self.seconds[phase] = self.seconds.get(phase, 0.0) + seconds
        solver.time = end  # the frame time exactly (steps land on it up to rounding)
        self.last = {"iterations": iterations, "residual": residual, "steps": steps}
        self.frame += 1
        for observer in self.observers:
            observer(self)

    def frame_values(self) -> dict[str, Any]:
        s = self.solver
        return {
            "time": self.time,
            "fluid/position": s.position,
            "fluid/velocity": s.velocity,
            "fluid/pressure": s.pressure,
            "fluid/number_density": s.number_density,
            "fluid/alive": s.alive,
            "solver/iterations": self.last["iterations"],
            "solver/residual": self.last["residual"],
            "solver/steps": self.last["steps"],
        }

    def datasets(self) -> list[Dataset]:
        n, dim = self.solver.position.shape
        return [
            Dataset("time", (), "s"),
            Dataset("fluid/position", (n, dim), "m"),
            Dataset("fluid/velocity", (n, dim), "m/s"),
            Dataset("fluid/pressure", (n,), "Pa"),
            Dataset("fluid/number_density", (n,), "1"),
            Dataset("fluid/alive", (n,), "1", np.bool_),
            Dataset("solver/iterations", (), "1", np.int32),
            Dataset("solver/residual", (), "1"),
            Dataset("solver/steps", (), "1", np.int32),
        ]

    def attributes(self, scene_toml: str) -> dict[str, Any]:
        from jellysim.simulation import result_attributes

        return {
            **result_attributes(self.scene, scene_toml),
            "particle_spacing": self.scene.fluid.spacing,
            "fluid_particles": int(np.sum(self.solver.kind == FLUID)),
            **self.geometry,
        }

    def writer(
        self, path: Path, scene_toml: str, initial: dict[str, np.ndarray] | None = None
    ) -> ResultWriter:
        return ResultWriter(
            path,
            self.datasets(),
            self.attributes(scene_toml),
            initial,
            static={"fluid/kind": (self.solver.kind, "1")},
        )

    def checkpoint_state(self) -> dict[str, np.ndarray]:
        return {**self.solver.state_arrays(), "last": np.array(list(self.last.values()))}

    def restore(self, frame: int, state: dict[str, np.ndarray]) -> None:
        last = state.pop("last")
        self.solver.restore(state)
        self.last = {
            "iterations": int(last[0]),
            "residual": float(last[1]),
            "steps": int(last[2]),
        }
        self.frame = frame

    def finish(self) -> None:
        """Report what the run did: particles that left the domain, time per phase."""
        dead = int(np.sum(~self.solver.alive))
        if dead:
            log.warning("%d particles left the domain (fluid/alive is False for them)", dead)
        if self.seconds:
            total = sum(self.seconds.values())
            parts = ", ".join(f"{k} {v / total:.0%}" for k, v in self.seconds.items())
            log.info("fluid time per phase: %s", parts)
