"""One tentacle side by side with PyElastica 1.0.0: wall time and tip sway.

    /work/venv-bench/bin/python benchmarks/bench_pyelastica.py [--quick] [--threads N]
                                                               [--repeats R]

The scene: one chain of 61 particles (60 segments, 0.6 m) of diameter d = 0.01 m and Young's
modulus 0.24 MPa, neutrally buoyant, root clamped along -z and moved by 0.05 sin(2 pi t) m along
x, across water flowing at 0.3 m/s along -z (root to tip), sphere drag at every particle
(docs/theory/tentacle.md Eq. T4-T5). jellysim runs it at its own substep; PyElastica runs a
Cosserat rod with the same node masses, the same EI, the same drag (jellysim's own ``drag_gain``
applied at every node as a PyElastica force) and a driven clamp, with PositionVerlet at the
largest stable dt, frame / n with n found by bisection (a whole number of steps per frame, so
that both codes sample the tip at the same times).

Reports, for 3 s and 30 s simulated (3 s only with ``--quick``): wall times of the time loops
over ``--repeats`` runs (start-up excluded: jellysim's ``Simulation.prepare()``, PyElastica's
``finalize()`` and its first-call compilation are timed apart), their ratio, the tip sway
(peak-to-peak tip x over the last simulated second, sampled at the 30 fps frames) of each and
their relative difference; then, for the longest duration, each code's tip sway at a smaller dt
(PyElastica's / 4, jellysim's ``solver.dt_safety = 0.1``: convergence in dt) and the wall time
of one ``jellysim.run`` with output on.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import math
import os
import platform
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass

import numba
import numpy as np
from numba import njit

import jellysim
from jellysim import Scene, Simulation
from jellysim.tentacle.kernels import drag_gain

try:
    import elastica
except ImportError:
    sys.exit("bench_pyelastica: PyElastica is not installed; pip install -e .[bench]")

OVERRIDES = {
    "bell.model": "none",
    "tentacles.count": 1,
    "tentacles.particles": 61,
    "tentacles.spacing": 0.01,
    "tentacles.youngs_modulus": 2.4e5,
    "tentacles.bending": "euler-bernoulli",  # EI with I = pi d^4 / 64, as in the Cosserat rod
    "tentacles.root": "clamped",
    "tentacles.rest_curvature": 0.0,  # straight at rest, as the Cosserat rod (brown-jelly curls)
    "tentacles.rest_curvature_tip": 0.0,
    "flow.speed": 0.3,
    "flow.noise": 0.0,
    "root_motion.amplitude": 0.05,
    "root_motion.frequency": 1.0,
    "root_motion.direction": [1.0, 0.0, 0.0],  # across the flow
}
DURATIONS = (3.0, 30.0)  # s simulated
SWAY_WINDOW = 1.0  # s: the tip sway is taken over the last second
WARM_UP_DURATION = 0.1  # s: a throw-away run of each code for its first calls
HANG = np.array([0.0, 0.0, -1.0])  # the tentacle's rest direction, root to tip (the clamp's)

# Bisection of PyElastica's stable dt: its bracket (s) and probe length (s).
DT_BRACKET = (1.0e-5, 1.0e-2)
PROBE_DURATION = 3.0
MAX_STRETCH = 0.1  # a probe whose element lengths leave rest +-10 % has blown up
# The convergence checks: PyElastica's dt divided by REFINE; jellysim's solver.dt_safety.
REFINE = 4
FINE_DT_SAFETY = 0.1
SWAY_TOLERANCE = 0.05  # the agreement of the tip sways
TARGET_SPEEDUP = 20.0  # the target wall-time ratio


def scene_for(duration: float, dt_safety: float = 1.0) -> Scene:
    # brown-jelly's marginal group alone (no oral arms) as a one-table scene
    marginal = jellysim.load_scene("brown-jelly").group_scene(0)
    return jellysim.load_scene(
        marginal, {**OVERRIDES, "duration": duration, "solver.dt_safety": dt_safety}
    )


def tip_sway(tip_x: np.ndarray, fps: float) -> float:
    """Peak-to-peak (m) of the frames' tip x over the last ``SWAY_WINDOW`` s."""
    last = tip_x[-(round(SWAY_WINDOW * fps) + 1) :]
    return float(last.max() - last.min())


@dataclass(frozen=True)
class Run:
    """One timed run: the time step (s), loop wall time (s), tip x per frame (m), and whether it
    stayed stable (PyElastica: finite, every element within ``MAX_STRETCH`` of its rest length,
    tip sway below the tentacle's length; jellysim raises SimulationUnstable instead)."""

    dt: float
    wall: float
    tip_x: np.ndarray
    stable: bool


# --- jellysim ---------------------------------------------------------------------------------


def run_jellysim(scene: Scene) -> tuple[Run, float]:
    """Time ``step_frame`` over the whole scene; also return ``prepare()``'s time (JIT or cache)."""
    simulation = Simulation(scene)
    start = time.perf_counter()
    simulation.prepare()
    prepare = time.perf_counter() - start
    tip_x = np.empty(scene.frame_count)
    tip_x[0] = simulation.positions[0, -1, 0]
    start = time.perf_counter()
    for frame in range(1, scene.frame_count):
        simulation.step_frame()
        tip_x[frame] = simulation.positions[0, -1, 0]
    wall = time.perf_counter() - start
    return Run(simulation.plan.dt, wall, tip_x, True), prepare


# --- PyElastica -------------------------------------------------------------------------------


@njit(cache=True)
def add_sphere_drag(
    velocities: np.ndarray,
    water_velocity: np.ndarray,
    diameter: float,
    density: float,
    viscosity: float,
    forces: np.ndarray,
) -> None:
    """Add jellysim's sphere drag ``k(|u_r|) u_r`` (N), Eq. (T5), at every node.

    ``velocities``, ``forces``: (3, n_nodes), PyElastica's layout; ``u_r = water_velocity - v``.
    """
    for i in range(velocities.shape[1]):
        r0 = water_velocity[0] - velocities[0, i]
        r1 = water_velocity[1] - velocities[1, i]
        r2 = water_velocity[2] - velocities[2, i]
        k = drag_gain(math.sqrt(r0 * r0 + r1 * r1 + r2 * r2), diameter, density, viscosity)
        forces[0, i] += k * r0
        forces[1, i] += k * r1
        forces[2, i] += k * r2


class SphereDrag(elastica.NoForces):
    """jellysim's particle drag (paper Eq. 3-5) on every node of a rod: a sphere of diameter d
    in water moving uniformly at ``water_velocity`` (m/s). No torque, no added mass."""

    def __init__(
        self, water_velocity: np.ndarray, diameter: float, density: float, viscosity: float
    ) -> None:
        super().__init__()
        self.water_velocity = np.asarray(water_velocity, dtype=np.float64)
        self.diameter = diameter
        self.density = density
        self.viscosity = viscosity

    def apply_forces(self, system: elastica.CosseratRod, time: float = 0.0) -> None:
        add_sphere_drag(
            system.velocity_collection,
            self.water_velocity,
            self.diameter,
            self.density,
            self.viscosity,
            system.external_forces,
        )


class DrivenClamp(elastica.ConstraintBase):
    """Node 0 at ``p0 + amplitude sin(2 pi f t) direction`` with the matching velocity; the first
    element's directors held at their initial value and its angular velocity at zero."""

    def __init__(
        self,
        root_position: np.ndarray,
        root_directors: np.ndarray,
        amplitude: float,
        frequency: float,
        direction: np.ndarray,
        **kwargs: object,
    ) -> None:
        super().__init__(**kwargs)
        self.root_position = root_position.copy()
        self.root_directors = root_directors.copy()
        self.amplitude = amplitude
        self.omega = 2.0 * math.pi * frequency
        self.direction = np.asarray(direction, dtype=np.float64)

    def constrain_values(self, system: elastica.CosseratRod, time: float) -> None:
        offset = self.amplitude * math.sin(self.omega * time)
        system.position_collection[:, 0] = self.root_position + offset * self.direction
        system.director_collection[:, :, 0] = self.root_directors

    def constrain_rates(self, system: elastica.CosseratRod, time: float) -> None:
        speed = self.amplitude * self.omega * math.cos(self.omega * time)
        system.velocity_collection[:, 0] = speed * self.direction
        system.omega_collection[:, 0] = 0.0


class TentacleSimulator(elastica.BaseSystemCollection, elastica.Constraints, elastica.Forcing):
    pass


def build_rod(scene: Scene) -> tuple[TentacleSimulator, elastica.CosseratRod]:
    """The scene's tentacle as a finalized Cosserat rod.

    Node masses equal jellysim's particle masses: a rod element holds rho pi (d/2)^2 d and each
    node half of both neighbours, i.e. rho pi d^3 / 4 inside and half at the tip, as jellysim
    lumps them (the root node is prescribed in both). Shear modulus E / 3 (incompressible).
    Every node starts moving with the root, as jellysim's chain does.
    """
    t = scene.tentacles
    rm = scene.root_motion
    root = np.array([scene.bell.radius, 0.0, 0.0])  # tentacle 0 of the still margin
    rod = elastica.CosseratRod.straight_rod(
        t.particles - 1,
        root,
        HANG,
        np.array([1.0, 0.0, 0.0]),
        (t.particles - 1) * t.spacing,
        0.5 * t.spacing,
        scene.tentacle_density,
        youngs_modulus=t.youngs_modulus,
        shear_modulus=t.youngs_modulus / 3.0,
    )
    direction = np.asarray(rm.direction, dtype=np.float64)
    rod.velocity_collection[:] = (rm.amplitude * 2.0 * math.pi * rm.frequency * direction)[:, None]
    simulator = TentacleSimulator()
    simulator.append(rod)
    simulator.constrain(rod).using(
        DrivenClamp,
        constrained_position_idx=(0,),
        constrained_director_idx=(0,),
        amplitude=rm.amplitude,
        frequency=rm.frequency,
        direction=direction,
    )
    simulator.add_forcing_to(rod).using(
        SphereDrag,
        water_velocity=-scene.flow.speed * np.array([0.0, 0.0, 1.0]),  # along -z, the bell axis
        diameter=t.spacing,
        density=scene.water.density,
        viscosity=scene.water.viscosity,
    )
    simulator.finalize()
    return simulator, rod


def run_pyelastica(scene: Scene, dt: float) -> tuple[Run, float]:
    """PositionVerlet at the largest step <= ``dt`` that divides a frame; stops at the first
    frame that blows up. Returns the run and the set-up time (rod, ``finalize()``)."""
    start = time.perf_counter()
    simulator, rod = build_rod(scene)
    setup = time.perf_counter() - start
    stepper = elastica.PositionVerlet()
    frame_dt = 1.0 / scene.fps
    steps = math.ceil(frame_dt / dt - 1e-9)
    h = frame_dt / steps
    tip_x = np.full(scene.frame_count, np.nan)
    tip_x[0] = rod.position_collection[0, -1]
    stable = True
    now = 0.0
    start = time.perf_counter()
    for frame in range(1, scene.frame_count):
        for _ in range(steps):
            now = stepper.step(simulator, now, h)
        tip_x[frame] = rod.position_collection[0, -1]
        stretch = np.abs(rod.lengths / rod.rest_lengths - 1.0).max()
        if not (math.isfinite(tip_x[frame]) and stretch < MAX_STRETCH):
            stable = False
            break
    wall = time.perf_counter() - start
    length = (scene.tentacles.particles - 1) * scene.tentacles.spacing
    stable = stable and tip_sway(tip_x, scene.fps) < length
    return Run(h, wall, tip_x, stable), setup


def bisect_stable_dt(scene: Scene) -> tuple[float, int]:
    """Largest PyElastica dt (s) that runs ``scene`` stably and divides its frame.

    Bisection on the steps per frame n (dt = frame / n, geometric midpoints) between the dt of
    ``DT_BRACKET`` (the small one assumed stable, the large one checked unstable), down to
    adjacent n: about 1 % in dt at n = 80. Returns the dt and the number of probes run.
    """
    frame_dt = 1.0 / scene.fps
    stable = math.ceil(frame_dt / DT_BRACKET[0])
    unstable = math.ceil(frame_dt / DT_BRACKET[1])
    if run_pyelastica(scene, frame_dt / unstable)[0].stable:
        raise RuntimeError(
            f"PyElastica is stable at dt = {frame_dt / unstable:g} s: widen the bracket"
        )
    probes = 1
    while stable - unstable > 1:
        trial = round(math.sqrt(stable * unstable))
        probes += 1
        if run_pyelastica(scene, frame_dt / trial)[0].stable:
            stable = trial
        else:
            unstable = trial
    return frame_dt / stable, probes


# --- report -----------------------------------------------------------------------------------


def span(values: list[float], digits: str = ".3g") -> str:
    low, high = min(values), max(values)
    if f"{low:{digits}}" == f"{high:{digits}}":
        return f"{low:{digits}}"
    return f"{low:{digits}}-{high:{digits}}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="3 s simulated only")
    parser.add_argument("--threads", type=int, default=numba.config.NUMBA_NUM_THREADS)
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per case")
    args = parser.parse_args()
    numba.set_num_threads(args.threads)
    durations = DURATIONS[:1] if args.quick else DURATIONS
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
        f"python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}, "
        f"jellysim {jellysim.__version__}, pyelastica {importlib.metadata.version('pyelastica')}; "
        f"numba threads {numba.get_num_threads()}; load average {os.getloadavg()[0]:.2f}"
    )

    # Start-up: first calls compile (fresh Numba cache) or load from the cache.
    _, prepare = run_jellysim(scene_for(WARM_UP_DURATION))
    start = time.perf_counter()
    run_pyelastica(scene_for(WARM_UP_DURATION), 1.0e-3)
    pyelastica_first = time.perf_counter() - start
    print(
        f"start-up: jellysim Simulation.prepare() {prepare:.2f} s; PyElastica build, finalize() "
        f"and first calls {pyelastica_first:.2f} s (JIT compile or Numba cache load)"
    )

    start = time.perf_counter()
    probe = scene_for(PROBE_DURATION)
    dt_stable, probes = bisect_stable_dt(probe)
    steps = round(1.0 / (probe.fps * dt_stable))
    print(
        f"PyElastica's largest stable dt: {dt_stable:.4g} s = frame / {steps} "
        f"(bisection over {DT_BRACKET[0]:g}-{DT_BRACKET[1]:g} s to one step per frame, "
        f"{PROBE_DURATION:g} s probes: finite, "
        f"element lengths within {MAX_STRETCH:.0%}, tip sway < L; {probes} probes, "
        f"{time.perf_counter() - start:.1f} s)"
    )

    print()
    print(
        f"{'simulated':>9} {'code':>10} {'dt [s]':>9} {'wall [s]':>13} {'start-up [s]':>12} "
        f"{'tip sway [m]':>13}"
    )
    results = {}
    for duration in durations:
        scene = scene_for(duration)
        jelly, elastic = [], []
        for _ in range(args.repeats):  # interleaved, so that the VM's drifts hit both alike
            jelly.append(run_jellysim(scene))
            elastic.append(run_pyelastica(scene, dt_stable))
        if not all(run.stable for run, _ in elastic):
            print(f"PyElastica went unstable at dt = {dt_stable:.4g} s over {duration:g} s")
        for name, runs in (("jellysim", jelly), ("PyElastica", elastic)):
            walls = [run.wall for run, _ in runs]
            setups = [setup for _, setup in runs]
            run = runs[0][0]
            sway = tip_sway(run.tip_x, scene.fps)
            print(
                f"{duration:>8g}s {name:>10} {run.dt:>9.3g} {span(walls):>13} "
                f"{span(setups, '.2f'):>12} {sway:>13.5f}"
            )
        results[duration] = (jelly, elastic)
        ratios = [e.wall / j.wall for (j, _), (e, _) in zip(jelly, elastic, strict=True)]
        median = statistics.median(e.wall for e, _ in elastic) / statistics.median(
            j.wall for j, _ in jelly
        )
        difference = (
            tip_sway(jelly[0][0].tip_x, scene.fps) / tip_sway(elastic[0][0].tip_x, scene.fps) - 1.0
        )
        print(f"{'':>9} {'ratio':>10} {'':>9} {f'{median:.3g}x':>13} {'':>12} {difference:>+13.2%}")
        print(
            f"{'':>9} {'':>10} {'':>9} {f'({span(ratios)}x)':>13} {'':>12} "
            f"{'within' if abs(difference) <= SWAY_TOLERANCE else 'OUTSIDE'} "
            f"{SWAY_TOLERANCE:.0%}; target >= {TARGET_SPEEDUP:g}x "
            f"{'met' if median >= TARGET_SPEEDUP else 'NOT met'}"
        )

    duration = durations[-1]
    print()
    print(f"convergence in dt, {duration:g} s simulated (tip sway, m):")
    scene = scene_for(duration)
    jelly_fine, _ = run_jellysim(scene_for(duration, dt_safety=FINE_DT_SAFETY))
    elastic_fine, _ = run_pyelastica(scene, dt_stable / REFINE)
    jelly_own = results[duration][0][0][0]
    elastic_own = results[duration][1][0][0]
    for name, own, fine in (
        ("jellysim", jelly_own, jelly_fine),
        ("PyElastica", elastic_own, elastic_fine),
    ):
        a, b = tip_sway(own.tip_x, scene.fps), tip_sway(fine.tip_x, scene.fps)
        print(
            f"  {name:>10}: dt {own.dt:.3g} s: {a:.5f}; dt {fine.dt:.3g} s: {b:.5f} "
            f"({a / b - 1.0:+.2%}); wall {fine.wall:.2f} s"
        )
    fine_ratio = tip_sway(jelly_fine.tip_x, scene.fps) / tip_sway(elastic_fine.tip_x, scene.fps)
    print(f"  fine-dt jellysim vs fine-dt PyElastica: {fine_ratio - 1.0:+.2%}")

    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        jellysim.run(scene_for(duration), folder, quiet=True).close()
        wall = time.perf_counter() - start
    print(
        f"\njellysim.run, {duration:g} s simulated, output on (result.h5 every frame, "
        f"checkpoints; set-up and cache load included): {wall:.3f} s"
    )
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
