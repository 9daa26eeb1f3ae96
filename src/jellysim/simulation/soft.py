"""Case 2 of the paper: the mass-spring bell pulsing in the MPS fluid, driving its tentacles.

One frame (paper Fig. 6, §4.2.2-4.2.4, run in one pass):

1. The fluid and the bell advance together to the next frame time in MPS steps of the stable dt
   (the fluid's limits and the springs' explicit limit); each step the bell's spring and muscle
   forces enter MPS's explicit stage as a force density on the bell particles, which are fluid
   particles in every other stage.
2. The bell records its margin at the new frame: tentacle base points with their velocities,
   clamp directions, the margin polyline (:meth:`jellysim.bell.soft.SoftBell.record`).
3. The tentacles advance through the frame, their roots driven by cubic Hermite interpolation
   between the two recorded frames (C1 in time).

The MPS arrays hold the water first, then the bell particles, then the tank; ``fluid/*`` in the
result are the water and the tank, ``bell/*`` the bell.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np

from jellysim.bell.soft import SoftBell
from jellysim.config import Scene
from jellysim.fluid.geometry import FLUID
from jellysim.fluid.mps import FluidDiverged, MPSSolver, substep
from jellysim.io.result import Dataset, ResultWriter
from jellysim.simulation.fluid import fluid_particles, mps_parameters

log = logging.getLogger(__name__)

# kappa of the fluid's acceleration limit under gravity, dt <= kappa sqrt(l0 / g): gravity moves a
# particle at rest g dt^2 / 2 = kappa^2 l0 / 2 = 0.0006 l0 in a step. Measured (docs/soft-bell.md):
# the coarse test bell stays still at 18 steps a 0.1 s frame at l0 = 0.25 m (g dt^2 / 2 = 0.0006
# l0 a step); at 13 steps (0.0012 l0) the relaxed bell sinks 2.7 times as far and the swim's third
# pulse is lost. kappa in [0.0348, 0.0356) gives both the coarse test's 18 steps and the preset's
# measured 12 (l0 = 0.16 m, 1/20 s frames).
STILL_WATER_ACCELERATION_NUMBER = 0.035


class SoftBellSimulation:
    """The soft bell in its tank and, when the scene has tentacles, the tentacles it drives."""

    def __init__(self, scene: Scene) -> None:
        from jellysim.simulation import Simulation

        self.scene = scene
        self.tentacles = Simulation(scene) if scene.tentacles.count > 0 else None
        bell = self.tentacles.driver if self.tentacles is not None else SoftBell(scene)
        assert isinstance(bell, SoftBell)
        self.bell = bell
        positions, kinds, self.geometry = fluid_particles(scene)
        in_bell = (kinds == FLUID) & bell.shell(positions)
        if not np.array_equal(positions[in_bell], bell.rest):
            raise RuntimeError("the bell's particles are not the carved lattice cells")
        water = np.flatnonzero((kinds == FLUID) & ~in_bell)
        tank = np.flatnonzero(kinds != FLUID)
        order = np.concatenate([water, np.flatnonzero(in_bell), tank])
        self.bell_rows = slice(len(water), len(water) + int(in_bell.sum()))
        self.fluid_rows = np.concatenate(
            [np.arange(len(water)), np.arange(self.bell_rows.stop, len(order))]
        )
        # Weightless water has nothing to fall: the fluid's speed alone sets the CFL step. Under
        # gravity the water starts at rest and stays there, but without a bound the first step from
        # rest is a whole 0.05 s frame at the preset's resolution and the surface is thrown off at
        # 50 m/s within 0.25 s. The bound is on gravity's work in a step: dt <= kappa sqrt(l0 / g),
        # a particle at rest falling g dt^2 / 2 = kappa^2 l0 / 2 before the pressure holds it, with
        # kappa = STILL_WATER_ACCELERATION_NUMBER (docs/soft-bell.md, "The time step under
        # gravity"). The fluid-only scenes' free fall over the water's height, sqrt(2 g H), would
        # take 17 steps a frame at the preset's resolution instead of 12.
        params = dataclasses.replace(
            mps_parameters(scene),
            free_fall_floor=False,
            acceleration_number=STILL_WATER_ACCELERATION_NUMBER,
        )
        self.solver = MPSSolver(params, positions[order], kinds[order])
        self.l0 = scene.fluid.spacing
        self.frame_dt = 1.0 / scene.fps
        # the springs' explicit limit, unless they are integrated implicitly
        self.spring_dt = bell.stable_dt() if bell.integration == "explicit" else math.inf
        self.frame = 0
        self.observers: list[Any] = []
        self.last = {"iterations": 0, "residual": 0.0, "steps": 0}
        self.seconds: dict[str, float] = {}
        self._force = np.zeros_like(self.solver.position)
        self._bell_force = np.zeros_like(bell.rest)

    @property
    def time(self) -> float:
        return self.frame * self.frame_dt

    def describe(self) -> str:
        s = self.scene
        water = self.bell_rows.start
        text = (
            f"mass-spring bell of {len(self.bell.rest)} particles and "
            f"{len(self.bell.springs.pairs)} springs ({int(self.bell.springs.muscle.sum())} "
            f"muscle, {self.bell.integration} integration) in MPS 3-D water of {water} "
            f"particles, l0 = {s.fluid.spacing:g} m"
        )
        if self.tentacles is not None:
            text += f"; {self.tentacles.describe()}"
        return text

    def prepare(self) -> None:
        """Compile the kernels (or load them from the cache) on throw-away copies."""
        probe = MPSSolver(self.solver.params, self.solver.position.copy(), self.solver.kind)
        probe.restore(self.solver.state_arrays())
        rows = self.bell_rows
        self.bell.step_force(
            probe.position[rows], probe.velocity[rows], 0.0, 1e-3, self._bell_force.copy()
        )
        try:
            probe.step(min(probe.stable_dt(), 1e-6), self._force)
        except FluidDiverged:
            pass  # the first real step reports it, with its time; it compiles what is left
        if self.tentacles is not None:
            self.tentacles.prepare()

    def step_frame(self) -> None:
        """Advance water, bell and tentacles to the next frame time."""
        from jellysim.errors import SimulationUnstable

        end = (self.frame + 1) * self.frame_dt
        solver, bell, rows = self.solver, self.bell, self.bell_rows
        iterations, residual, steps = 0, 0.0, 0
        volume = self.l0**3
        while solver.time < end - 1e-12 * self.frame_dt:
            dt = substep(end - solver.time, min(solver.stable_dt(), self.spring_dt))
            bell.step_force(
                solver.position[rows], solver.velocity[rows], solver.time, dt, self._bell_force
            )
            self._force[rows] = self._bell_force / volume  # force density, N/m3
            try:
                stats = solver.step(dt, self._force)
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
        solver.time = end
        if not np.all(solver.alive[rows]):
            raise SimulationUnstable(
                f"bell particles left the tank at t = {end:.6g} s; lower fluid.courant",
                time=end,
            )
        self.last = {"iterations": iterations, "residual": residual, "steps": steps}
        self.frame += 1
        bell.record(self.frame, solver.position[rows].copy(), solver.velocity[rows].copy())
        if self.tentacles is not None:
            self.tentacles.step_frame()
        for observer in self.observers:
            observer(self)

    def frame_values(self) -> dict[str, Any]:
        s, rows = self.solver, self.fluid_rows
        if self.tentacles is not None:
            values = self.tentacles.frame_values()
        else:
            values = {
                "time": self.time,
                "bell/margin": self.bell.margin(self.time),
                **self.bell.frame_values(self.time),
            }
        values.update(
            {
                "fluid/position": s.position[rows],
                "fluid/velocity": s.velocity[rows],
                "fluid/pressure": s.pressure[rows],
                "fluid/number_density": s.number_density[rows],
                "fluid/alive": s.alive[rows],
                "solver/iterations": self.last["iterations"],
                "solver/residual": self.last["residual"],
                "solver/steps": self.last["steps"],
            }
        )
        return values

    def datasets(self) -> list[Dataset]:
        n = len(self.fluid_rows)
        if self.tentacles is not None:
            own = self.tentacles.datasets()
        else:
            own = [
                Dataset("time", (), "s"),
                Dataset("bell/margin", (self.bell.sectors, 3), "m"),
                *self.bell.frame_datasets(),
            ]
        return [
            *own,
            # float32: the water is for pictures and ParaView here, and 57k particles a frame
            # add up; checkpoints keep the full state in float64.
            Dataset("fluid/position", (n, 3), "m", np.float32),
            Dataset("fluid/velocity", (n, 3), "m/s", np.float32),
            Dataset("fluid/pressure", (n,), "Pa", np.float32),
            Dataset("fluid/number_density", (n,), "1", np.float32),
            Dataset("fluid/alive", (n,), "1", np.bool_),
            Dataset("solver/iterations", (), "1", np.int32),
            Dataset("solver/residual", (), "1"),
            Dataset("solver/steps", (), "1", np.int32),
        ]

    def attributes(self, scene_toml: str) -> dict[str, Any]:
        from jellysim.simulation import result_attributes

        attributes = {
            **result_attributes(self.scene, scene_toml),
            "bell_model": "mass-spring",
            "particle_spacing": self.l0,
            "fluid_particles": self.bell_rows.start,
            "bell_particles": len(self.bell.rest),
            "bell_springs": len(self.bell.springs.pairs),
            "muscle_springs": int(self.bell.springs.muscle.sum()),
            "bell_spring_dt": self.spring_dt,
            **self.geometry,
        }
        if self.tentacles is not None:
            attributes["tentacle_dt"] = self.tentacles.plan.dt
            attributes["tentacle_substeps"] = self.tentacles.plan.substeps
        return attributes

    def writer(
        self, path: Path, scene_toml: str, initial: dict[str, np.ndarray] | None = None
    ) -> ResultWriter:
        return ResultWriter(
            path,
            self.datasets(),
            self.attributes(scene_toml),
            initial,
            static={
                "fluid/kind": (self.solver.kind[self.fluid_rows], "1"),
                **self.bell.static_datasets(),
            },
        )

    def checkpoint_state(self) -> dict[str, np.ndarray]:
        state = {
            **{f"fluid_{k}": v for k, v in self.solver.state_arrays().items()},
            "last": np.array(list(self.last.values())),
        }
        if self.tentacles is not None:
            for name, value in self.tentacles.checkpoint_state().items():
                state[f"tentacles_{name}"] = value
        return state

    def restore(self, frame: int, state: dict[str, np.ndarray]) -> None:
        """Continue after ``frame``: the fluid and bell state, the bell's record of that frame
        (a function of the bell particles, so recomputed bitwise), the tentacles."""
        self.solver.restore({k[6:]: v for k, v in state.items() if k.startswith("fluid_")})
        last = state["last"]
        self.last = {"iterations": int(last[0]), "residual": float(last[1]), "steps": int(last[2])}
        self.frame = frame
        rows, solver = self.bell_rows, self.solver
        self.bell.records.clear()
        self.bell.record(frame, solver.position[rows].copy(), solver.velocity[rows].copy())
        if self.tentacles is not None:
            self.tentacles.restore(
                frame,
                {k[10:]: v for k, v in state.items() if k.startswith("tentacles_")},
            )

    def finish(self) -> None:
        dead = int(np.sum(~self.solver.alive))
        if dead:
            log.warning("%d fluid particles left the domain (fluid/alive is False)", dead)
        if self.seconds:
            total = sum(self.seconds.values())
            parts = ", ".join(f"{k} {v / total:.0%}" for k, v in self.seconds.items())
            log.info("fluid time per phase: %s", parts)
