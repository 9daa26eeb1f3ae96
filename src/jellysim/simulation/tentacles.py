"""Tentacles driven at their roots (paper §4.1): the loop of Case 1 and of the forced base point,
and the tentacles the soft bell drives in Case 2.

Parameters are built once (``model``, ``medium``, ``plan``); the state ``positions`` and
``velocities`` (T, P, 3) is mutated in place. Per frame Python samples the roots and the flow at
the substep times (vectorised NumPy), then one compiled call advances all substeps of all chains.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from jellysim import fields
from jellysim.bell import BellModel, make_root_driver
from jellysim.config import Scene
from jellysim.errors import SimulationUnstable
from jellysim.fields import Dataset
from jellysim.io.result import frame_datasets
from jellysim.simulation.loop import Simulation, register_loop
from jellysim.tentacle import kernels
from jellysim.tentacle.flow import flow_noise_for, water_velocity
from jellysim.tentacle.kernels import advance_frame, rest_shape_positions
from jellysim.tentacle.model import (
    chain_model_for,
    characteristic_speed,
    curl_normals,
    medium_for,
    plan_substeps,
    rest_shape_for,
)
from jellysim.tentacle.roots import Forcing, RootDriver

# Watchdog: a chain whose RMS speed exceeds this multiple of the scene's speed scale has run away.
RUNAWAY_SPEED_FACTOR = 100.0


@register_loop("tentacles")
class TentacleSimulation(Simulation):
    """One scene's tentacles and what drives their roots.

    ``driver``: the root driver handed in (the soft bell's recorded margin), or by default the
    scene's bell model, whose body datasets then join the result. State (mutated in place, never
    rebound): ``positions``, ``velocities`` (T, P, 3) in m, m/s; ``diagnostics`` (T, 3) per
    chain: largest length error, most projection iterations, first failed substep (-1: none).
    Scene data built once: ``rest_shape`` (T, P, 3) m, each chain's rest second differences in
    its transported frames (zeros: straight; docs/theory/tentacle.md §6), and ``outward`` (T, 3)
    the unit outward radial direction of each root at t = 0, the rest curl's reference in the
    bell frame.
    """

    def __init__(self, scene: Scene, driver: RootDriver | None = None) -> None:
        super().__init__(scene)
        self.bell: BellModel | None = None
        if driver is None:
            self.bell = make_root_driver(scene)
            driver = self.bell
        self.driver: RootDriver = driver
        forcing = driver.forcing()
        self.model = chain_model_for(scene)
        self.medium = medium_for(scene)
        self.noise = flow_noise_for(scene)
        self.plan = plan_substeps(scene, forcing)
        t = scene.tentacles
        self.positions = np.empty((t.count, t.particles, 3))
        self.velocities = np.empty((t.count, t.particles, 3))
        self.diagnostics = np.zeros((t.count, 3))
        self.rest_shape = rest_shape_for(scene)
        self.curled = bool(np.any(self.rest_shape != 0.0))
        self.outward = self._outward() if self.curled else np.zeros((t.count, 3))
        self.reset()
        self.speed_limit = RUNAWAY_SPEED_FACTOR * self._speed_scale(forcing)

    def _speed_scale(self, forcing: Forcing) -> float:
        """A speed the tentacles should never much exceed (m/s)."""
        s = self.scene
        length = (s.tentacles.particles - 1) * s.tentacles.spacing
        g = float(np.linalg.norm(s.water.gravity))
        contrast = abs(s.tentacle_density - s.water.density) / s.tentacle_density
        return characteristic_speed(s, forcing) + math.sqrt(g * length * contrast) + 0.1

    def _outward(self) -> np.ndarray:
        """Unit outward directions (T, 3) of the roots at t = 0, perpendicular to the bell
        axis, from the margin's centre (zero rows for a root on the axis)."""
        roots = self.driver.roots(np.zeros(1))[0][0]
        axis = self.driver.axis(np.zeros(1))[0]
        radial = roots - self.driver.margin(0.0).mean(axis=0)
        radial -= (radial @ axis)[:, None] * axis
        size = np.linalg.norm(radial, axis=1)
        return np.where(size[:, None] > 0.0, radial / np.maximum(size, 1e-300)[:, None], 0.0)

    def curl_normals(self, times: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Root-frame normals (S, T, 3) of the rest shapes at ``times`` given the clamp
        directions (S, T, 3): the outward direction carried with the bell axis (the minimal
        rotation from the axis at t = 0), made perpendicular to the clamp direction; zeros for
        straight chains, which do not use them."""
        if not self.curled:
            return np.zeros_like(directions)
        a = self.driver.axis(np.zeros(1))[0]
        b = self.driver.axis(times)  # (S, 3)
        cross = np.cross(a, b)[:, None, :]  # (S, 1, 3): the rotation a -> b about a x b
        cos = (b @ a)[:, None, None]
        u = self.outward[None, :, :]  # (1, T, 3)
        along = np.sum(cross * u, axis=2)[..., None]
        outward = cos * u + np.cross(cross, u) + along / (1.0 + cos) * cross
        return np.ascontiguousarray(curl_normals(directions, outward, b))

    def reset(self) -> None:
        """Frame 0: every tentacle in its rest shape from its root (straight along its clamp
        direction unless it has a rest curl), moving rigidly with its root (no impulsive
        start)."""
        times = np.zeros(1)
        roots, root_velocities, directions = self.driver.roots(times)
        self._rim = (0, roots[0], root_velocities[0])  # (frame, rim, rim velocity)
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
        self.frame = 0

    def substep_times(self, frame: int) -> np.ndarray:
        """End times (s) of the substeps that lead from ``frame`` to ``frame + 1``."""
        n = self.plan.substeps
        return (frame * n + np.arange(1, n + 1)) * (self.frame_dt / n)

    def prepare(self) -> None:
        """Compile the kernels (or load them from Numba's cache) on a throw-away copy of the
        state, so that the first frame's timing, and the progress bar's ETA, are honest."""
        times = self.substep_times(self.frame)[:1]
        roots, root_velocities, directions = self.driver.roots(times)
        kernels.advance_frame(  # the kernel itself: a stand-in for the step is not compiled here
            self.positions.copy(),
            self.velocities.copy(),
            roots,
            root_velocities,
            directions,
            self.curl_normals(times, directions),
            self.rest_shape,
            np.zeros_like(roots),
            self.model,
            self.medium,
            self.plan.dt,
            self.diagnostics.copy(),
        )

    def step_frame(self) -> None:
        """Advance the tentacles by one frame; raise SimulationUnstable if they diverged."""
        times = self.substep_times(self.frame)
        # The roots follow the margin, C1 in time (paper §4.1, §4.2.4).
        roots, root_velocities, directions = self.driver.roots(times)
        # The surrounding flow relative to the bell, with smooth noise (§4.1.2).
        flow = water_velocity(
            self.scene.flow.speed,
            self.driver.axis(times),
            self.driver.bell_velocity(times),
            self.noise.sample(times),
        )
        # The rest shape's root frame, fixed in the bell frame (docs/theory/tentacle.md §6).
        normals = self.curl_normals(times, directions)
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
        )
        self.frame += 1
        self._rim = (self.frame, roots[-1], root_velocities[-1])  # what drove the roots last
        self.notify()
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
        values = {
            fields.TIME.path: self.time,
            fields.TENTACLE_POSITION.path: self.positions,
            fields.TENTACLE_VELOCITY.path: self.velocities,
            fields.TENTACLE_CONSTRAINT_ERROR.path: float(self.diagnostics[:, 0].max(initial=0.0)),
            fields.TENTACLE_PROJECTION_ITERATIONS.path: int(
                self.diagnostics[:, 1].max(initial=0.0)
            ),
            fields.BELL_RIM.path: rim,
            fields.BELL_RIM_VELOCITY.path: rim_velocity,
            fields.BELL_MARGIN.path: self.driver.margin(self.time),
        }
        if self.bell is not None:
            values.update(self.bell.frame_values(self.time))
        return values

    def describe(self) -> str:
        t = self.scene.tentacles
        return f"{t.count} tentacles x {t.particles} particles, {self.plan.describe()}"

    def finish(self) -> None:
        """Nothing to report beyond the result."""

    def checkpoint_state(self) -> dict[str, np.ndarray]:
        return {"positions": self.positions, "velocities": self.velocities}

    def restore(self, frame: int, state: dict[str, np.ndarray]) -> None:
        """Continue from a checkpoint's state after ``frame``."""
        self.positions[:] = state["positions"]
        self.velocities[:] = state["velocities"]
        self.frame = frame

    def datasets(self) -> list[Dataset]:
        t = self.scene.tentacles
        own = frame_datasets(t.count, t.particles, self.driver.margin(0.0).shape[0])
        return own + (self.bell.frame_datasets() if self.bell is not None else [])

    def static_datasets(self) -> dict[str, tuple[np.ndarray, str]]:
        return self.bell.static_datasets() if self.bell is not None else {}

    def links(self) -> dict[str, str]:
        return self.bell.links() if self.bell is not None else {}

    def attributes(self, scene_toml: str) -> dict[str, Any]:
        return {
            **super().attributes(scene_toml),
            "tentacle_dt": self.plan.dt,
            "tentacle_substeps": self.plan.substeps,
            "bell_model": self.scene.bell.model,
        }
