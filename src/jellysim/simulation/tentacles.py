"""Tentacles driven at their roots (paper §4.1): the loop of Case 1 and of the forced base point,
and the tentacles the soft bell drives in Case 2.

Each group of identical tentacles (docs/groups.md) is a :class:`ChainGroup`: its parameters are
built once (``model``, ``medium``, ``plan``, its own substep), its state ``positions`` and
``velocities`` (Tg, Pg, 3) is mutated in place. Per frame Python samples the roots and the flow at
the group's substep times (vectorised NumPy), then one compiled call advances all substeps of all
its chains. Groups do not act on each other; they share the root driver, which places every
root (:mod:`jellysim.tentacle.layout`). A one-table scene is one group, run exactly as before.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from jellysim import fields
from jellysim.bell import BellModel, make_root_driver
from jellysim.config import Scene
from jellysim.config.schema import DEFAULT_GROUP
from jellysim.errors import SimulationUnstable
from jellysim.fields import Dataset
from jellysim.io.result import frame_datasets
from jellysim.simulation.loop import Simulation, register_loop
from jellysim.tentacle import kernels
from jellysim.tentacle.contact import Obstacle, no_obstacle, shell_obstacle
from jellysim.tentacle.flow import flow_at_tentacles, flow_noise_for
from jellysim.tentacle.kernels import advance_frame, rest_shape_positions
from jellysim.tentacle.layout import RootLayout, root_layout
from jellysim.tentacle.model import (
    carried_curl_normals,
    chain_model_for,
    characteristic_speed,
    medium_for,
    plan_substeps,
    rest_shape_for,
)
from jellysim.tentacle.roots import Forcing, RootDriver

NO_OBSTACLE = no_obstacle()
# Watchdog: a chain whose RMS speed exceeds this multiple of the scene's speed scale has run away.
RUNAWAY_SPEED_FACTOR = 100.0


class _GroupDriver:
    """The root driver as one group sees it: the roots of its rows only."""

    def __init__(self, driver: RootDriver, rows: slice) -> None:
        self.driver = driver
        self.rows = rows

    def roots(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        positions, velocities, directions = self.driver.roots(times)
        r = self.rows
        return (
            np.ascontiguousarray(positions[:, r]),
            np.ascontiguousarray(velocities[:, r]),
            np.ascontiguousarray(directions[:, r]),
        )

    def bell_velocity(self, times: np.ndarray) -> np.ndarray:
        return self.driver.bell_velocity(times)

    def axis(self, times: np.ndarray) -> np.ndarray:
        return self.driver.axis(times)

    def margin(self, time: float) -> np.ndarray:
        return self.driver.margin(time)

    def forcing(self) -> Forcing:
        return self.driver.forcing()


def group_seed(seed: int, group: int) -> int:
    """The flow-noise seed of group ``group``: the scene's for the first group, then an
    independent stream per group (NumPy's SeedSequence of (seed, group))."""
    if group == 0:
        return seed
    state = np.random.SeedSequence([seed, group]).generate_state(1, np.uint64)[0]
    return int(state >> np.uint64(1))


class ChainGroup:
    """One group's tentacles and what drives their roots.

    ``scene``: the scene as the group sees it (its keys as ``[tentacles]``); ``driver``: the
    roots of this group's tentacles; ``rows``: their numbers among all tentacles. State (mutated
    in place, never rebound): ``positions``, ``velocities`` (Tg, Pg, 3) in m, m/s;
    ``diagnostics`` (Tg, 3) per chain: largest length error, most projection iterations, first
    failed substep (-1: none). Scene data built once: ``rest_shape`` (Tg, Pg, 3) m, each
    chain's rest second differences in its transported frames (zeros: straight;
    docs/theory/tentacle.md §6), and ``outward`` (Tg, 3) the unit outward radial direction of
    each root at t = 0, the rest curl's reference in the bell frame.
    """

    def __init__(
        self, scene: Scene, driver: RootDriver, rows: slice, frame_dt: float, name: str
    ) -> None:
        self.scene = scene
        self.driver = driver
        self.rows = rows
        self.name = name
        self.frame_dt = frame_dt
        forcing = driver.forcing()
        self.model = chain_model_for(scene)
        self.medium = medium_for(scene)
        self.noise = flow_noise_for(scene)
        self.plan = plan_substeps(scene, forcing)
        t = scene.tentacles
        self.positions = np.empty((t.count, t.particles, 3))
        self.velocities = np.empty((t.count, t.particles, 3))
        self.diagnostics = np.zeros((t.count, 3))
        # The water's drag impulse on each particle over the frame (N s), kept only where it
        # acts back on the water (flow.two_way).
        self.drag_impulse = np.zeros((t.count, t.particles if scene.flow.two_way else 0, 3))
        self.rest_shape = rest_shape_for(scene)
        self.curled = bool(np.any(self.rest_shape != 0.0))
        self.outward = self._outward() if self.curled else np.zeros((t.count, 3))
        self.speed_limit = RUNAWAY_SPEED_FACTOR * self._speed_scale(forcing)

    def _speed_scale(self, forcing: Forcing) -> float:
        """A speed the tentacles should never much exceed (m/s)."""
        s = self.scene
        length = (s.tentacles.particles - 1) * s.tentacles.spacing
        g = float(np.linalg.norm(s.water.gravity))
        contrast = abs(s.tentacle_density - s.water.density) / s.tentacle_density
        return characteristic_speed(s, forcing) + math.sqrt(g * length * contrast) + 0.1

    def _outward(self) -> np.ndarray:
        """Unit outward directions (Tg, 3) of the roots at t = 0, perpendicular to the bell
        axis, from the margin's centre (zero rows for a root on the axis)."""
        roots = self.driver.roots(np.zeros(1))[0][0]
        axis = self.driver.axis(np.zeros(1))[0]
        radial = roots - self.driver.margin(0.0).mean(axis=0)
        radial -= (radial @ axis)[:, None] * axis
        size = np.linalg.norm(radial, axis=1)
        return np.where(size[:, None] > 0.0, radial / np.maximum(size, 1e-300)[:, None], 0.0)

    def curl_normals(self, times: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Root-frame normals (S, Tg, 3) of the rest shapes at ``times`` given the clamp
        directions (S, Tg, 3): the outward direction carried with the bell axis (the minimal
        rotation from the axis at t = 0), made perpendicular to the clamp direction; zeros for
        straight chains, which do not use them."""
        if not self.curled:
            return np.zeros_like(directions)
        a = self.driver.axis(np.zeros(1))[0]
        b = self.driver.axis(times)  # (S, 3)
        # The rotation a -> b about a x b carries the outward directions.
        return carried_curl_normals(np.cross(a, b), b @ a, self.outward, directions, b)

    def reset(self) -> tuple[np.ndarray, np.ndarray]:
        """Frame 0: every tentacle in its rest shape from its root (straight along its clamp
        direction unless it has a rest curl), moving rigidly with its root (no impulsive
        start). Returns the roots and their velocities (Tg, 3) that placed them."""
        times = np.zeros(1)
        roots, root_velocities, directions = self.driver.roots(times)
        t = self.scene.tentacles
        if self.curled:
            normals = self.curl_normals(times, directions)
            for chain in range(t.count):
                rest_shape_positions(
                    roots[0, chain],
                    directions[0, chain],
                    normals[0, chain],
                    self.rest_shape[chain],
                    t.spacing,
                    self.positions[chain],
                )
        else:
            offsets = np.arange(t.particles) * t.spacing
            self.positions[:] = (
                roots[0][:, None, :] + offsets[None, :, None] * directions[0][:, None, :]
            )
        self.velocities[:] = root_velocities[0][:, None, :]
        return roots[0], root_velocities[0]

    def substep_times(self, frame: int) -> np.ndarray:
        """End times (s) of the substeps that lead from ``frame`` to ``frame + 1``."""
        n = self.plan.substeps
        return (frame * n + np.arange(1, n + 1)) * (self.frame_dt / n)

    def prepare(self, frame: int) -> None:
        """Compile the kernels (or load them from Numba's cache) on a throw-away copy of the
        state."""
        times = self.substep_times(frame)[:1]
        roots, root_velocities, directions = self.driver.roots(times)
        kernels.advance_frame(  # the kernel itself: a stand-in for the step is not compiled here
            self.positions.copy(),
            self.velocities.copy(),
            roots,
            root_velocities,
            directions,
            self.curl_normals(times, directions),
            self.rest_shape,
            np.zeros_like(roots)[:, :, None],
            self.model,
            self.medium,
            self.plan.dt,
            self.diagnostics.copy(),
            self.drag_impulse.copy(),
            NO_OBSTACLE,
        )
        kernels.chain_health(self.positions, self.velocities)  # the watchdog's

    def step_frame(
        self, frame: int, water: np.ndarray | None = None, obstacle: Obstacle | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Advance the group by one frame from ``frame``; the substep times, and the roots and
        their velocities (Tg, 3) at the last of them. ``water`` (Tg, Pg, 3) m/s: the simulated
        water's velocity at each particle, held over the frame (``flow.model = "fluid"``);
        ``obstacle``: the bell's shell over the frame, kept out of (``bell.tentacle_contact``)."""
        times = self.substep_times(frame)
        # The roots follow the margin, C1 in time (paper §4.1, §4.2.4).
        roots, root_velocities, directions = self.driver.roots(times)
        noise = self.noise.sample(times)
        if water is not None:
            # The simulated water at each particle, with the noise (docs/theory/soft-bell.md §8).
            flow = water[None, :, :, :] + noise[:, :, None, :]
        else:
            # The surrounding flow relative to the bell, with smooth noise (§4.1.2).
            flow = flow_at_tentacles(
                self.scene.flow,
                self.driver.axis(times),
                self.driver.bell_velocity(times),
                noise,
            )[:, :, None, :]
        # The rest shape's root frame, fixed in the bell frame (docs/theory/tentacle.md §6).
        normals = self.curl_normals(times, directions)
        self.drag_impulse[:] = 0.0  # summed over this frame's substeps
        # Bending (Eq. 1-2) with the rest shape (Eq. T13), drag (Eq. 3-5) and inextensibility,
        # every substep of every chain.
        advance_frame(
            self.positions,
            self.velocities,
            roots,
            root_velocities,
            directions,
            normals,
            self.rest_shape,
            flow,
            self.model,
            self.medium,
            self.plan.dt,
            self.diagnostics,
            self.drag_impulse,
            obstacle if obstacle is not None else NO_OBSTACLE,
        )
        return times, roots[-1], root_velocities[-1]

    def check(self, times: np.ndarray, time: float) -> None:
        """Raise SimulationUnstable if a chain failed (in the substeps ending at ``times``),
        became non-finite or ran away by ``time``."""
        failed = self.diagnostics[:, 2]
        if np.any(failed >= 0):
            # The chain that failed first (lowest substep), the lowest index among equals.
            chain = int(np.argmin(np.where(failed >= 0, failed, np.inf)))
            when = float(times[int(failed[chain])])
            raise SimulationUnstable(
                f"unstable at t = {when:.6g} s in {self.label(chain)}: the state became "
                "non-finite or the length constraint could not be met; lower "
                "solver.dt_safety or check the scene's forces",
                time=when,
                tentacle=self.rows.start + chain,
            )
        rms, finite = kernels.chain_health(self.positions, self.velocities)
        if not np.all(finite):
            chain = int(np.argmax(~finite))
            raise SimulationUnstable(
                f"unstable at t = {time:.6g} s in {self.label(chain)}: the state became "
                "non-finite; lower solver.dt_safety or check the scene's forces",
                time=time,
                tentacle=self.rows.start + chain,
            )
        if np.any(rms > self.speed_limit):
            chain = int(np.argmax(rms > self.speed_limit))
            raise SimulationUnstable(
                f"runaway energy at t = {time:.6g} s in {self.label(chain)}: RMS speed "
                f"{rms[chain]:.3g} m/s exceeds {self.speed_limit:.3g} m/s; lower "
                "solver.dt_safety or check the scene's forces",
                time=time,
                tentacle=self.rows.start + chain,
            )

    def label(self, chain: int) -> str:
        """``tentacle N`` (N among all tentacles), with the group's name where it has one."""
        number = self.rows.start + chain
        if self.name == DEFAULT_GROUP:
            return f"tentacle {number}"
        return f"tentacle {number} (group {self.name!r})"


def tentacle_water_attributes(scene: Scene, names: Sequence[str]) -> dict[str, Any]:
    """The root attributes that say what each tentacle group is and what water it felt:
    ``tentacle_groups`` (names), ``tentacle_flow`` (``flow.model``, "fluid-two-way" where the
    tentacles act back on the water) and ``tentacle_drag`` (each group's drag law)."""
    flow = scene.flow.model + ("-two-way" if scene.flow.two_way else "")
    return {
        "tentacle_groups": list(names),
        "tentacle_flow": flow,
        "tentacle_drag": [g.tentacles.drag for g in scene.groups],
    }


@register_loop("tentacles")
class TentacleSimulation(Simulation):
    """One scene's tentacles, group by group, and what drives their roots.

    ``driver``: the root driver handed in (the soft bell's recorded margin), or by default the
    scene's bell model, whose body datasets then join the result. ``groups``: one
    :class:`ChainGroup` per group of the scene. ``positions``, ``velocities`` (T, P, 3): in a
    one-group scene the group's own state (mutated in place, never rebound); with several
    groups, all tentacles gathered, P the longest chain's particles and the rows beyond a
    shorter chain's own NaN (a copy: write through :meth:`restore` or a group's arrays).
    """

    def __init__(self, scene: Scene, driver: RootDriver | None = None) -> None:
        super().__init__(scene)
        self.bell: BellModel | None = None
        # The simulated water's velocity at points (N, 3) -> (N, 3) m/s, set by a loop that runs
        # a fluid (flow.model = "fluid").
        self.water_sampler: Callable[[np.ndarray], np.ndarray] | None = None
        # Takes the drag impulses (N, 3) N s at the points (N, 3) where the water was sampled,
        # once a frame (flow.two_way): the reaction on the water.
        self.water_reaction: Callable[[np.ndarray, np.ndarray], None] | None = None
        # The bell's shell (vertices at the frame's start and end, faces) over the frame from
        # the given frame, which the tentacles are kept out of (bell.tentacle_contact): set here
        # for a kinematic bell, by the soft-bell loop for its drawn skin.
        self.bell_shell: Callable[[int], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
        if driver is None:
            self.bell = make_root_driver(scene)
            driver = self.bell
            shell = self.bell.shell()
            if shell is not None:
                surface, faces = shell
                dt = self.frame_dt
                self.bell_shell = lambda frame: (
                    surface(frame * dt),
                    surface((frame + 1) * dt),
                    faces,
                )
        self.driver: RootDriver = driver
        self.layout: RootLayout = root_layout(scene)
        single = len(scene.groups) == 1
        self.groups: list[ChainGroup] = []
        for index, rows in enumerate(self.layout.slices()):
            group_scene = scene.group_scene(index)
            if index > 0:
                group_scene = dataclasses.replace(group_scene, seed=group_seed(scene.seed, index))
            self.groups.append(
                ChainGroup(
                    group_scene,
                    driver if single else _GroupDriver(driver, rows),
                    rows,
                    self.frame_dt,
                    scene.groups[index].name,
                )
            )
        self.reset()

    # The one-group scene's state and parameters, as before groups (scripts, tests).

    @property
    def model(self) -> Any:
        return self.groups[0].model

    @property
    def medium(self) -> Any:
        return self.groups[0].medium

    @property
    def plan(self) -> Any:
        """The first group's substep plan (every group's: :attr:`groups`)."""
        return self.groups[0].plan

    @property
    def noise(self) -> Any:
        return self.groups[0].noise

    @property
    def rest_shape(self) -> np.ndarray:
        return self._gather([g.rest_shape for g in self.groups], 0.0)

    @property
    def diagnostics(self) -> np.ndarray:
        if len(self.groups) == 1:
            return self.groups[0].diagnostics
        return np.concatenate([g.diagnostics for g in self.groups])

    @property
    def speed_limit(self) -> float:
        return self.groups[0].speed_limit

    @property
    def positions(self) -> np.ndarray:
        return self._gather([g.positions for g in self.groups], math.nan)

    @property
    def velocities(self) -> np.ndarray:
        return self._gather([g.velocities for g in self.groups], math.nan)

    def _gather(self, arrays: list[np.ndarray], fill: float) -> np.ndarray:
        """Group arrays (Tg, Pg, 3) as one (T, P, 3), shorter chains padded with ``fill``."""
        if len(arrays) == 1:
            return arrays[0]
        out = np.full((self.layout.count, self.scene.max_particles, 3), fill)
        for group, array in zip(self.groups, arrays, strict=True):
            out[group.rows, : array.shape[1]] = array
        return out

    def curl_normals(self, times: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """The first group's rest-frame normals (see :meth:`ChainGroup.curl_normals`)."""
        return self.groups[0].curl_normals(times, directions)

    def reset(self) -> None:
        """Frame 0: every tentacle in its rest shape from its root, moving with its root."""
        placed = [g.reset() for g in self.groups]
        if len(self.groups) == 1:
            self._rim = (0, *placed[0])  # (frame, rim, rim velocity)
        else:
            self._rim = (
                0,
                np.concatenate([p[0] for p in placed]),
                np.concatenate([p[1] for p in placed]),
            )
        self.frame = 0

    def substep_times(self, frame: int) -> np.ndarray:
        """The first group's substep end times from ``frame`` to ``frame + 1``."""
        return self.groups[0].substep_times(frame)

    def prepare(self) -> None:
        """Compile the kernels (or load them from Numba's cache) on a throw-away copy of the
        state, so that the first frame's timing, and the progress bar's ETA, are honest."""
        for group in self.groups:
            group.prepare(self.frame)

    def step_frame(self) -> None:
        """Advance the tentacles by one frame; raise SimulationUnstable if they diverged."""
        sampled = [self._water(group) for group in self.groups]
        # Where the water was sampled: where its reaction goes (Eq. S2).
        starts = [g.positions.reshape(-1, 3).copy() for g in self.groups]
        obstacle = self._obstacle()
        done = [
            (group, group.step_frame(self.frame, water, obstacle))
            for group, water in zip(self.groups, sampled, strict=True)
        ]
        if self.water_reaction is not None:
            impulses = [g.drag_impulse.reshape(-1, 3) for g in self.groups]
            self.water_reaction(np.concatenate(starts), np.concatenate(impulses))
        self.frame += 1
        if len(done) == 1:
            _, (times, rim, rim_velocity) = done[0]
            self._rim = (self.frame, rim, rim_velocity)  # what drove the roots last
        else:
            self._rim = (
                self.frame,
                np.concatenate([d[1][1] for d in done]),
                np.concatenate([d[1][2] for d in done]),
            )
        self.notify()
        for group, (times, _, _) in done:
            group.check(times, self.time)

    def _obstacle(self) -> Obstacle | None:
        """The bell's shell over this frame where the tentacles are kept out of it."""
        if not self.scene.bell.tentacle_contact or self.bell_shell is None:
            return None
        return shell_obstacle(*self.bell_shell(self.frame))

    def _water(self, group: ChainGroup) -> np.ndarray | None:
        """The simulated water's velocity (Tg, Pg, 3) at ``group``'s particles where the scene's
        flow is the fluid's (``water_sampler`` set by the loop that runs the fluid), else None."""
        if self.scene.flow.model != "fluid":
            return None
        if self.water_sampler is None:
            raise RuntimeError("flow.model = 'fluid' needs the fluid loop's water sampler")
        points = group.positions.reshape(-1, 3)
        return self.water_sampler(points).reshape(group.positions.shape)

    def frame_values(self) -> dict[str, Any]:
        """The current frame as the result store's datasets."""
        frame, rim, rim_velocity = self._rim
        if frame != self.frame:  # the state was set from outside (a resume, a script)
            roots, root_velocities, _ = self.driver.roots(np.array([self.time]))
            rim, rim_velocity = roots[0], root_velocities[0]
        diagnostics = self.diagnostics
        values = {
            fields.TIME.path: self.time,
            fields.TENTACLE_POSITION.path: self.positions,
            fields.TENTACLE_VELOCITY.path: self.velocities,
            fields.TENTACLE_CONSTRAINT_ERROR.path: float(diagnostics[:, 0].max(initial=0.0)),
            fields.TENTACLE_PROJECTION_ITERATIONS.path: int(diagnostics[:, 1].max(initial=0.0)),
            fields.BELL_RIM.path: rim,
            fields.BELL_RIM_VELOCITY.path: rim_velocity,
            fields.BELL_MARGIN.path: self.driver.margin(self.time),
        }
        if self.bell is not None:
            values.update(self.bell.frame_values(self.time))
        return values

    def describe(self) -> str:
        parts = []
        for group in self.groups:
            t = group.scene.tentacles
            text = f"{t.count} tentacles x {t.particles} particles, {group.plan.describe()}"
            parts.append(text if group.name == DEFAULT_GROUP else f"{group.name}: {text}")
        return "; ".join(parts)

    def finish(self) -> None:
        """Nothing to report beyond the result."""

    def checkpoint_state(self) -> dict[str, np.ndarray]:
        return {"positions": self.positions, "velocities": self.velocities}

    def restore(self, frame: int, state: dict[str, np.ndarray]) -> None:
        """Continue from a checkpoint's state after ``frame``."""
        for group in self.groups:
            p = group.positions.shape[1]
            group.positions[:] = state["positions"][group.rows, :p]
            group.velocities[:] = state["velocities"][group.rows, :p]
        self.frame = frame

    def datasets(self) -> list[Dataset]:
        own = frame_datasets(
            self.layout.count,
            self.groups[0].scene.tentacles.particles
            if len(self.groups) == 1
            else self.scene.max_particles,
            self.driver.margin(0.0).shape[0],
        )
        return own + (self.bell.frame_datasets() if self.bell is not None else [])

    def static_datasets(self) -> dict[str, tuple[np.ndarray, str]]:
        own = {
            fields.TENTACLE_GROUP.path: (self.layout.group, fields.TENTACLE_GROUP.units),
            fields.TENTACLE_PARTICLES.path: (
                self.layout.particles,
                fields.TENTACLE_PARTICLES.units,
            ),
        }
        return own | (self.bell.static_datasets() if self.bell is not None else {})

    def links(self) -> dict[str, str]:
        return self.bell.links() if self.bell is not None else {}

    def attributes(self, scene_toml: str) -> dict[str, Any]:
        return {
            **super().attributes(scene_toml),
            "tentacle_dt": self.plan.dt,
            "tentacle_substeps": self.plan.substeps,
            "bell_model": self.scene.bell.model,
            **tentacle_water_attributes(self.scene, self.layout.names),
        }
