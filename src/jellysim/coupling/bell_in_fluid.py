"""The soft bell in its water (paper §4.2.2, docs/theory/soft-bell.md §4).

The bell's particles are cells of the fluid's lattice (built once, here) carved out of the water;
the MPS arrays hold the water first, then the bell particles, then the tank. Each MPS step the
bell's spring and muscle forces enter the explicit stage as a force density ``F / l0^3`` on the
bell particles, which are fluid particles in every other stage; they feel gravity and buoyancy
like water (neutral buoyancy). After each frame the margin is recorded (:mod:`.margin`) to drive
the tentacle roots.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from jellysim.bell.kinematic import sector_count
from jellysim.bell.skin import BellSkin
from jellysim.bell.soft import BellShape, SoftBell
from jellysim.config.schema import Scene
from jellysim.coupling.margin import RecordedMargin, depth_inside, edge_offsets
from jellysim.coupling.water_at import spread_reaction
from jellysim.errors import SimulationUnstable
from jellysim.fluid.frames import FrameStats, advance_to, compile_on_copy
from jellysim.fluid.geometry import FLUID
from jellysim.fluid.mps import MPSParameters, PhaseTimer
from jellysim.fluid.setup import fluid_particles, make_solver, mps_parameters
from jellysim.tentacle.layout import root_layout

# kappa of the fluid's acceleration limit under gravity, dt <= kappa sqrt(l0 / g): gravity moves a
# particle at rest g dt^2 / 2 = kappa^2 l0 / 2 = 0.0006 l0 in a step. Measured (docs/soft-bell.md):
# the coarse test bell stays still at 18 steps a 0.1 s frame at l0 = 0.25 m (g dt^2 / 2 = 0.0006
# l0 a step); at 13 steps (0.0012 l0) the relaxed bell sinks 2.7 times as far and the swim's third
# pulse is lost. kappa in [0.0348, 0.0356) gives both the coarse test's 18 steps and the preset's
# measured 12 (l0 = 0.16 m, 1/20 s frames).
STILL_WATER_ACCELERATION_NUMBER = 0.035


def water_parameters(scene: Scene) -> MPSParameters:
    """The MPS parameters of the soft bell's water.

    Weightless water has nothing to fall: the fluid's speed alone sets the CFL step. Under
    gravity the water starts at rest and stays there, but without a bound the first step from
    rest is a whole 0.05 s frame at the preset's resolution and the surface is thrown off at
    50 m/s within 0.25 s. The bound is on gravity's work in a step: dt <= kappa sqrt(l0 / g),
    a particle at rest falling g dt^2 / 2 = kappa^2 l0 / 2 before the pressure holds it, with
    kappa = STILL_WATER_ACCELERATION_NUMBER (docs/soft-bell.md, "The time step under
    gravity"). The fluid-only scenes' free fall over the water's height, sqrt(2 g H), would
    take 17 steps a frame at the preset's resolution instead of 12.
    """
    return dataclasses.replace(
        mps_parameters(scene),
        free_fall_floor=False,
        acceleration_number=STILL_WATER_ACCELERATION_NUMBER,
    )


class BellInFluid:
    """The soft bell (``body``, its rendering ``skin``) in its tank (``solver``), and the
    ``margin`` recorded from it. ``position`` and ``velocity`` (B, 3) m, m/s are the bell
    particles at the last recorded frame."""

    def __init__(self, scene: Scene) -> None:
        positions, kinds, self.geometry = fluid_particles(scene)
        shape = BellShape(scene)
        in_bell = (kinds == FLUID) & shape.shell(positions)
        rest = positions[in_bell]
        water = np.flatnonzero((kinds == FLUID) & ~in_bell)
        tank = np.flatnonzero(kinds != FLUID)
        order = np.concatenate([water, np.flatnonzero(in_bell), tank])
        self.bell_rows = slice(len(water), len(water) + len(rest))
        self.fluid_rows = np.concatenate(
            [np.arange(len(water)), np.arange(self.bell_rows.stop, len(order))]
        )
        params = water_parameters(scene)
        # the water on the CPU or the GPU (fluid.device); the springs beside it
        self.solver: Any = make_solver(params, positions[order], kinds[order], scene.fluid.device)
        self.on_gpu = scene.fluid.device == "cuda"
        l0 = params.l0
        self.body = SoftBell(scene, shape, rest)
        layout = root_layout(scene)
        sectors = sector_count(layout.margin_sectors(), 0)
        self.skin = BellSkin(shape, rest, sectors, l0)
        self.margin = RecordedMargin(
            shape, rest, l0, sectors, layout, 1.0 / scene.fps, self.body.forcing()
        )
        placement = scene.bell.root_placement
        if placement == "edge":
            # The margin roots start on the drawn margin's outer edge (issues 25-26).
            self.margin.set_drop(*edge_offsets(self.margin.rest_margin, self.skin.rim()))
        elif placement == "surface":
            # The margin roots start on the drawn surface's underside, not in the wall (issue 25).
            self.margin.set_drop(
                depth_inside(self.margin.rest_margin, self.skin.rest_surface, self.skin.faces)
            )
        if scene.bell.arm_anchor == "subumbrella" and layout.any_mouth:
            # The oral arms hang from the drawn underside's centre by a stalk (issue 25).
            self.margin.set_mouth_anchor(*self.skin.underside_centre())
        # the springs' explicit limit, unless they are integrated implicitly
        self.spring_dt = self.body.stable_dt() if self.body.integration == "explicit" else math.inf
        self.stats = FrameStats()
        self.position = rest.copy()
        self.velocity = np.zeros_like(rest)
        self._cell_volume = l0**3
        self._force = np.zeros_like(self.solver.position)
        self._bell_force = np.zeros_like(rest)
        # The tentacles' drag reaction (Eq. S2) as a force density (N/m3) over the next frame,
        # when it acts on the water (flow.two_way); None otherwise.
        self.reaction: np.ndarray | None = (
            np.zeros_like(self.solver.position) if scene.flow.two_way else None
        )
        # On the GPU the springs and muscle run there too: a step moves no particle array.
        self._gpu_springs: Any = None
        if self.on_gpu:
            from jellysim.bell.gpu_springs import GPUSprings

            self._gpu_springs = GPUSprings(self.body, self.solver, self.bell_rows, l0**3)

    @property
    def water_particles(self) -> int:
        return self.bell_rows.start

    def prepare(self) -> None:
        """Compile the springs' and the fluid's kernels on throw-away copies (the GPU's
        compile in the first step)."""
        if self.on_gpu:
            return
        rows = self.bell_rows
        self.body.step_force(
            self.solver.position[rows].copy(),
            self.solver.velocity[rows].copy(),
            0.0,
            1e-3,
            self._bell_force.copy(),
        )
        compile_on_copy(self.solver, self._force)

    def _spring_force_density(self, time: float, dt: float) -> Any:
        """The bell's springs and muscle over the step from ``time`` (Eq. B8-B9), as the force
        density (N/m3) of the explicit stage on the bell's rows (§4.2.2): a host array, or on
        the GPU a device array. Its wall time is the run's "springs" phase (the log's time
        per phase). On the GPU that is the implicit solve's, which waits for its answer; the
        explicit springs' kernels run on after their launch, and their time falls in the
        water's "explicit" phase."""
        with PhaseTimer(self.stats.seconds)("springs"):
            return self._springs(time, dt)

    def _springs(self, time: float, dt: float) -> Any:
        if self._gpu_springs is not None:
            return self._gpu_springs.force_density(time, dt)
        rows, solver = self.bell_rows, self.solver
        self.body.step_force(
            solver.position[rows], solver.velocity[rows], time, dt, self._bell_force
        )
        if self.reaction is None:
            self._force[rows] = self._bell_force / self._cell_volume
        else:
            np.copyto(self._force, self.reaction)
            self._force[rows] += self._bell_force / self._cell_volume
        return self._force

    def take_reaction(self, points: np.ndarray, impulses: np.ndarray, frame_dt: float) -> None:
        """The tentacles' drag impulses (N, 3) N s at ``points`` (N, 3) over the frame just
        taken, given back to the water and the bell as a force density over the next frame
        (Eq. S2): the momentum ``-sum J`` reaches the water in the explicit stages of the next
        frame's MPS steps, whose lengths add up to ``frame_dt``."""
        solver = self.solver
        fluid = np.flatnonzero(solver.alive & (solver.kind == FLUID))
        momentum = spread_reaction(
            points, impulses, solver.position[fluid], solver.constants.re_number_density
        )
        reaction = np.zeros_like(solver.position)
        reaction[fluid] = momentum / (frame_dt * self._cell_volume)
        self.set_reaction(reaction)

    def set_reaction(self, reaction: np.ndarray) -> None:
        """The tentacles' reaction (N, D) N/m3 that acts over the next frame (flow.two_way; a
        checkpoint's, on resuming), on the GPU too where the water is there."""
        assert self.reaction is not None
        self.reaction[:] = reaction
        if self._gpu_springs is not None:
            self._gpu_springs.set_reaction(self.reaction)

    def advance(self, end: float, frame_dt: float) -> None:
        """Water and bell together to the time ``end`` (s), in MPS steps of at most the stable
        dt of the fluid and of the springs' explicit limit."""
        advance_to(
            self.solver, end, frame_dt, self.stats, self.spring_dt, self._spring_force_density
        )
        if not np.all(self.solver.alive[self.bell_rows]):
            raise SimulationUnstable(
                f"bell particles left the tank at t = {end:.6g} s; lower fluid.courant",
                time=end,
            )

    def record(self, frame: int) -> None:
        """The bell at ``frame`` and the margin it drives the roots with (Eq. B10)."""
        rows = self.bell_rows
        self.position = self.solver.position[rows].copy()
        self.velocity = self.solver.velocity[rows].copy()
        self.margin.record(frame, self.position, self.velocity)

    def restore(self, frame: int, state: dict[str, np.ndarray], stats: np.ndarray) -> None:
        """Continue after ``frame`` from the solver's ``state`` arrays; the margin's record of
        that frame is a function of the bell particles, so it is recomputed bitwise."""
        self.solver.restore(state)
        self.stats.restore(stats)
        rows = self.bell_rows
        self.position = self.solver.position[rows].copy()
        self.velocity = self.solver.velocity[rows].copy()
        self.margin.restart(frame, self.position, self.velocity)
