"""Case 2 of the paper: the mass-spring bell pulsing in the MPS fluid, driving its tentacles.

One frame (paper Fig. 6, §4.2.2-4.2.4) is three named stages, each in its own module:

1. :meth:`BellInFluid.advance`: water and bell to the next frame time, the springs and the muscle
   in MPS's explicit stage (Eq. B8-B9, §4.2.2);
2. :meth:`BellInFluid.record`: the margin recorded at the new frame (Eq. B10, §4.2.4);
3. the tentacles through the frame, their roots driven by cubic Hermite interpolation between the
   two recorded frames (Eq. B11), :class:`jellysim.simulation.tentacles.TentacleSimulation`.

``fluid/*`` in the result are the water and the tank, ``bell/*`` the bell.
"""

from __future__ import annotations

from functools import partial
from typing import Any

import numpy as np

from jellysim import fields
from jellysim.config import Scene
from jellysim.coupling.bell_in_fluid import BellInFluid
from jellysim.coupling.water_at import solver_water_velocity_at
from jellysim.fields import Dataset
from jellysim.simulation.fluid import fluid_datasets, fluid_values, report
from jellysim.simulation.loop import Simulation, register_loop
from jellysim.simulation.tentacles import TentacleSimulation, tentacle_water_attributes


@register_loop("soft-bell")
class SoftBellSimulation(Simulation):
    """The soft bell in its tank (``coupling``) and, when the scene has tentacles, the tentacles
    its margin drives (``tentacles``)."""

    def __init__(self, scene: Scene) -> None:
        super().__init__(scene)
        self.coupling = BellInFluid(scene)
        self.tentacles = (
            TentacleSimulation(scene, self.coupling.margin) if scene.tentacle_count > 0 else None
        )
        if self.tentacles is not None and scene.flow.model == "fluid":
            # The tentacles feel the water at each particle at the frame's end (Eq. S1).
            solver = self.coupling.solver
            self.tentacles.water_sampler = partial(solver_water_velocity_at, solver)
            if scene.flow.two_way:
                # Their drag acts back on the water over the next frame (Eq. S2).
                self.tentacles.water_reaction = partial(
                    self.coupling.take_reaction, frame_dt=self.frame_dt
                )

    def describe(self) -> str:
        c = self.coupling
        springs = c.body.springs
        text = (
            f"mass-spring bell of {len(c.body.rest)} particles and {len(springs.pairs)} springs "
            f"({int(springs.muscle.sum())} muscle, {c.body.integration} integration) in MPS 3-D "
            f"water of {c.water_particles} particles, l0 = {c.solver.params.l0:g} m"
        )
        if self.tentacles is not None:
            text += f"; {self.tentacles.describe()}"
        return text

    def prepare(self) -> None:
        self.coupling.prepare()
        if self.tentacles is not None:
            self.tentacles.prepare()

    def step_frame(self) -> None:
        """Advance water, bell and tentacles to the next frame time."""
        c = self.coupling
        # The drawn skin at the frame's start: with the one at its end, the shell the tentacles
        # are kept out of over the frame (bell.tentacle_contact); only where they are.
        contact = self.tentacles is not None and self.scene.bell.tentacle_contact
        start = c.skin.surface(c.position) if contact else None
        # Water and bell to the frame time: springs and muscle in MPS's explicit stage
        # (Eq. B8-B9, §4.2.2), the bell particles fluid particles in every other stage.
        self.coupling.advance((self.frame + 1) * self.frame_dt, self.frame_dt)
        self.frame += 1
        # The margin recorded at the new frame: roots, clamp directions, polyline (Eq. B10).
        self.coupling.record(self.frame)
        # The tentacles through the frame, roots by cubic Hermite between records (Eq. B11).
        if self.tentacles is not None:
            if start is not None:
                shell = (start, c.skin.surface(c.position), c.skin.faces)
                self.tentacles.bell_shell = lambda frame: shell
            self.tentacles.step_frame()
        self.notify()

    def frame_values(self) -> dict[str, Any]:
        c = self.coupling
        if self.tentacles is not None:
            values = self.tentacles.frame_values()
        else:
            values = {
                fields.TIME.path: self.time,
                fields.BELL_MARGIN.path: c.margin.margin(self.time),
            }
        values.update(
            {
                fields.BELL_POSITION.path: c.position,
                fields.BELL_VELOCITY.path: c.velocity,
                fields.BELL_SURFACE_VERTICES.path: c.skin.surface(c.position).astype(np.float32),
                fields.BELL_CENTRE.path: c.position.mean(axis=0),
                fields.BELL_CONTRACTION.path: np.array(c.margin.contraction()),
                fields.BELL_ACTIVATION.path: np.array(c.body.activation(self.time)),
                **fluid_values(c.solver, c.fluid_rows, c.stats),
            }
        )
        return values

    def datasets(self) -> list[Dataset]:
        c = self.coupling
        bell = len(c.body.rest)
        if self.tentacles is not None:
            own = self.tentacles.datasets()
        else:
            own = [fields.TIME.dataset(), fields.BELL_MARGIN.dataset(R=c.margin.sectors)]
        return [
            *own,
            fields.BELL_POSITION.dataset(B=bell),
            fields.BELL_VELOCITY.dataset(B=bell),
            c.skin.dataset(),
            fields.BELL_CENTRE.dataset(),
            fields.BELL_CONTRACTION.dataset(),
            fields.BELL_ACTIVATION.dataset(),
            # float32: the water is for pictures and ParaView here, and 57k particles a frame
            # add up; checkpoints keep the full state in float64.
            *fluid_datasets(len(c.fluid_rows), 3, np.float32),
        ]

    def static_datasets(self) -> dict[str, tuple[np.ndarray, str]]:
        c = self.coupling
        return {
            fields.FLUID_KIND.path: (c.solver.kind[c.fluid_rows], fields.FLUID_KIND.units),
            **c.skin.static_datasets(),
            **c.body.static_datasets(),
            **(self.tentacles.static_datasets() if self.tentacles is not None else {}),
        }

    def attributes(self, scene_toml: str) -> dict[str, Any]:
        c = self.coupling
        attributes = {
            **super().attributes(scene_toml),
            "bell_model": "mass-spring",
            "particle_spacing": c.solver.params.l0,
            "fluid_particles": c.water_particles,
            "bell_particles": len(c.body.rest),
            "bell_springs": len(c.body.springs.pairs),
            "muscle_springs": int(c.body.springs.muscle.sum()),
            "bell_spring_dt": c.spring_dt,
            **c.geometry,
        }
        if self.tentacles is not None:
            attributes["tentacle_dt"] = self.tentacles.plan.dt
            attributes["tentacle_substeps"] = self.tentacles.plan.substeps
            attributes.update(tentacle_water_attributes(self.scene, self.tentacles.layout.names))
        return attributes

    def checkpoint_state(self) -> dict[str, np.ndarray]:
        state = {
            **{f"fluid_{k}": v for k, v in self.coupling.solver.state_arrays().items()},
            "last": self.coupling.stats.as_array(),
        }
        if self.tentacles is not None:
            for name, value in self.tentacles.checkpoint_state().items():
                state[f"tentacles_{name}"] = value
        if self.coupling.reaction is not None:  # the tentacles' reaction still to act
            state["coupling_reaction"] = self.coupling.reaction.copy()
        return state

    def restore(self, frame: int, state: dict[str, np.ndarray]) -> None:
        """Continue after ``frame``: the fluid and bell state, the margin's record of that
        frame, the tentacles."""
        fluid = {k[6:]: v for k, v in state.items() if k.startswith("fluid_")}
        self.coupling.restore(frame, fluid, state["last"])
        self.frame = frame
        if self.tentacles is not None:
            self.tentacles.restore(
                frame, {k[10:]: v for k, v in state.items() if k.startswith("tentacles_")}
            )
        if self.coupling.reaction is not None:
            self.coupling.set_reaction(state["coupling_reaction"])

    def finish(self) -> None:
        report(self.coupling.solver, self.coupling.stats)
