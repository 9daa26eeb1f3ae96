"""The fluid from one frame time to the next, in equal MPS steps of at most the stable dt."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from jellysim.errors import SimulationUnstable
from jellysim.fluid.mps import MPSSolver, substep
from jellysim.fluid.solvers import FluidDiverged

# Called before each step with (time, dt) in s: the external force density (N, D) N/m3, or None.
ExternalForce = Callable[[float, float], "np.ndarray | None"]

# The most MPS steps a frame may take, as the tentacles have theirs (tentacle.model.
# MAX_SUBSTEPS_PER_FRAME): a scene whose fluid needs more from the start is refused before it runs
# (jellysim.simulation.estimate), and a fluid whose stable step shrinks past it in a run has run
# away. An MPS step costs about 10 us a particle on two cores (docs/decisions.md, issue 24): ten
# thousand steps of the smallest preset's 900 particles take about 90 s a frame.
MAX_STEPS_PER_FRAME = 10_000


def steps_per_frame(frame_dt: float, dt: float) -> int:
    """The equal steps (:func:`jellysim.fluid.mps.substep`) of at most ``dt`` (s) that cover a
    frame of ``frame_dt`` (s)."""
    return max(1, math.ceil(frame_dt / dt - 1e-9))


@dataclass
class FrameStats:
    """What the steps of the last frame did: the last step's pressure-solver ``iterations`` and
    relative ``residual``, the number of ``steps``; ``seconds`` per phase over the whole run."""

    iterations: int = 0
    residual: float = 0.0
    steps: int = 0
    seconds: dict[str, float] = field(default_factory=dict)

    def as_array(self) -> np.ndarray:
        """(iterations, residual, steps) for a checkpoint."""
        return np.array([self.iterations, self.residual, self.steps])

    def restore(self, values: np.ndarray) -> None:
        self.iterations, self.residual = int(values[0]), float(values[1])
        self.steps = int(values[2])


def advance_to(
    solver: MPSSolver,
    end: float,
    frame_dt: float,
    stats: FrameStats,
    dt_limit: float = math.inf,
    external_force: ExternalForce | None = None,
    after_step: Callable[[float], None] | None = None,
) -> None:
    """Step ``solver`` to the time ``end`` (s) in equal steps of at most its stable dt and
    ``dt_limit`` (s) (:func:`jellysim.fluid.mps.substep`), landing on ``end`` exactly; the frame's
    figures go into ``stats``. A diverged pressure solve, or a stable step so short that the
    rest of the frame would take more than :data:`MAX_STEPS_PER_FRAME` steps, raises
    SimulationUnstable. ``after_step`` (if given) is called with each step's dt (s) after it
    (the probes' frame means)."""
    iterations, residual, steps = 0, 0.0, 0
    solver.begin_frame()
    while solver.time < end - 1e-12 * frame_dt:
        limit = min(solver.stable_dt(), dt_limit)
        if end - solver.time > MAX_STEPS_PER_FRAME * limit:
            raise SimulationUnstable(
                f"the fluid ran away at t = {solver.time:.6g} s: its stable step fell to "
                f"{limit:.3g} s, more than {MAX_STEPS_PER_FRAME} steps for the rest of the frame; "
                "lower fluid.courant or refine fluid.spacing",
                time=solver.time,
            )
        dt = substep(end - solver.time, limit)
        force = external_force(solver.time, dt) if external_force is not None else None
        try:
            step = solver.step(dt, force)
        except FluidDiverged as err:
            raise SimulationUnstable(
                f"the fluid diverged at t = {err.time:.6g} s: the pressure solve reached "
                f"{err.iterations} iterations with relative residual {err.residual:.3g}; "
                "lower fluid.courant or refine fluid.spacing",
                time=err.time,
            ) from None
        iterations, residual, steps = step.iterations, step.residual, steps + 1
        if after_step is not None:
            after_step(dt)
        for phase, seconds in step.seconds.items():
            stats.seconds[phase] = stats.seconds.get(phase, 0.0) + seconds
    solver.time = end  # the frame time exactly (steps land on it up to rounding)
    stats.iterations, stats.residual, stats.steps = iterations, residual, steps


def compile_on_copy(solver: MPSSolver, external_force: np.ndarray | None = None) -> None:
    """Compile the solver's kernels (or load them from Numba's cache) by one tiny step of a
    throw-away copy, so that the first frame's timing is honest."""
    probe = MPSSolver(solver.params, solver.position.copy(), solver.kind)
    probe.restore(solver.state_arrays())
    try:
        probe.step(min(probe.stable_dt(), 1e-6), external_force)
    except FluidDiverged:
        pass  # the first real step reports it, with its time; it compiles what is left
