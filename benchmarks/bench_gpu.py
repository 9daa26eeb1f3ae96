"""The MPS fluid on a GPU (fluid.device = "cuda") beside the CPU path: steps per second, the
time per phase, particle-steps per second and wall time per simulated second, and how far the
two paths' water is apart after the same steps.

    python benchmarks/bench_gpu.py [--case NAME ...] [--steps 20] [--cpu-threads 16]
        [--compare-steps 20] [--gpu-solver deflated|cg ...] [--precision double|single ...]
        [--grid-blocks N ...]

Cases, each from rest at its preset's scheme (the pressure to a relative residual of 1e-8):

- ``tank-3d``: the 3-D dam break of bench_fluid.py at a / l0 = 30 (54,000 fluid particles);
- ``moon-jelly-water``: moon-jelly's water without its bell (its tank, spacing and scheme: a
  filled 6.4 m tank at l0 = 0.16 m, 57,600 fluid particles, mixed source, corrected gradient),
  the fluid issue 28 asks 200 steps/s of;
- ``tank-3d-million``: tank-3d at a / l0 = 80 (1,024,000 fluid particles);
- ``spheric-test2-million``: the SPHERIC Test 2 preset at l0 = 0.161 / 17 = 9.5 mm (1,121,729
  fluid and 587,790 wall and dummy particles), its eight pressure probes read on the GPU each
  step as a run reads them (the steps from rest, before the column has gathered speed: the
  steps of the run's first moments, not its mean step).

``--gpu-solver deflated|cg`` (repeatable) times the GPU with each pressure solver in turn:
CG with Jacobi and the coarse correction, or with Jacobi alone (default: the preset's).
``--precision double|single`` (repeatable) times each solver with the pressure matrix's
off-diagonal entries in that precision in turn (fluid.matrix_precision; default: double).
``--grid-blocks N`` (repeatable) times the GPU again with each phase's cooperative grid cut to
at most N blocks, each N in turn on the same water (its steps follow the default's): fewer
blocks meet sooner at a grid barrier, more hide the memory's latency better.
``--cpu-threads N`` (0: none) also times the CPU path on N threads for the cases under 100,000
particles; ``--compare-steps K`` then steps both paths K times with the CPU's dt and prints the
largest distance between their fluid particles (the paths sum in other orders and solve with
other preconditioners: they agree to the solver's tolerance, which grows with the steps).
Walls and dummies are not counted in particle-steps.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numba
import numpy as np

import jellysim
from jellysim.fluid.geometry import FLUID
from jellysim.simulation.fluid import FluidSimulation

CASES: dict[str, tuple[str, dict[str, object]]] = {
    "tank-3d": ("tank-3d", {"fluid.spacing": 0.1 / 30}),
    "moon-jelly-water": (
        "hydrostatic-3d",
        {
            "fluid.spacing": 0.16,
            "fluid.tank_width": 6.4,
            "fluid.tank_depth": 6.4,
            "fluid.tank_height": 6.4,
            "fluid.water_height": 5.76,
            "fluid.lattice": "square",
            "fluid.surface": "standard",
            "fluid.surface_repulsion": False,
            "fluid.collision_distance": 0.5,
        },
    ),
    "tank-3d-million": ("tank-3d", {"fluid.spacing": 0.1 / 80}),
    "spheric-test2-million": ("spheric-test2", {"fluid.spacing": 0.161 / 17}),
}


def _time_steps(
    solver, steps: int, after_step=None
) -> tuple[float, dict[str, float], list[int], float]:
    """Seconds for ``steps`` steps at the stable dt (each followed by ``after_step(dt)``, the
    probes, where given), the seconds per phase, the iterations and the simulated time
    covered."""
    seconds: dict[str, float] = {}
    iterations = []
    started = solver.time
    clock = time.perf_counter()
    for _ in range(steps):
        dt = solver.stable_dt()
        stats = solver.step(dt)
        if after_step is not None:
            after_step(dt)
        iterations.append(stats.iterations)
        for phase, value in stats.seconds.items():
            seconds[phase] = seconds.get(phase, 0.0) + value
    return time.perf_counter() - clock, seconds, iterations, solver.time - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--case", choices=tuple(CASES), action="append")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--cpu-threads", type=int, default=0)
    parser.add_argument("--compare-steps", type=int, default=0)
    parser.add_argument(
        "--gpu-solver",
        choices=("deflated", "cg"),
        action="append",
        help="the GPU's pressure solver, each given timed in turn (default: the preset's)",
    )
    parser.add_argument(
        "--precision",
        choices=("double", "single"),
        action="append",
        help="fluid.matrix_precision, each given timed in turn (default: double)",
    )
    parser.add_argument(
        "--grid-blocks",
        type=int,
        action="append",
        default=[],
        help="the cooperative kernels' blocks at most, each given timed in turn after the default",
    )
    args = parser.parse_args()
    from jellysim.fluid import gpu

    if gpu.simulated():
        name = "none (Numba's CUDA simulator)"
    else:
        from numba import cuda

        name = str(cuda.get_current_device().name)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores; GPU {name!s}; "
        f"numba {numba.__version__}"
    )
    for case in args.case or list(CASES):
        preset, overrides = CASES[case]
        for solver in args.gpu_solver or [None]:
            for precision in args.precision or ["double"]:
                chosen = {**overrides, "fluid.matrix_precision": precision}
                fluid = _time_gpu(case, preset, chosen, solver, args.steps, args.grid_blocks)
        if args.cpu_threads > 0 and fluid <= 100_000:
            _time_cpu(case, preset, overrides, args.cpu_threads, args.steps)
            if args.compare_steps > 0:  # the preset's solver on both paths
                _compare(case, preset, overrides, args.compare_steps)


def _time_gpu(
    case: str,
    preset: str,
    overrides: dict[str, object],
    solver: str | None,
    steps: int,
    grid_blocks: list[int],
) -> int:
    """Times ``steps`` GPU steps of ``case`` with the pressure ``solver`` (None: the
    preset's), then as many more with each of ``grid_blocks`` (each phase's cooperative grid
    at most that many blocks), prints them, and returns its fluid particles."""
    chosen = {} if solver is None else {"fluid.solver": solver}
    scene = jellysim.load_scene(preset, {**overrides, **chosen, "fluid.device": "cuda"})
    clock = time.perf_counter()
    simulation = FluidSimulation(scene)
    device = simulation.solver
    fluid = int(np.sum(device.kind == FLUID))
    probes = simulation.probes
    after_step = None if probes is None else probes.after_step
    device.step(device.stable_dt())  # compiles the kernels
    if after_step is not None:
        after_step(0.0)  # compiles the probes' kernel
    first = time.perf_counter() - clock
    chosen_blocks = dict(getattr(device, "_blocks", {}))  # each cooperative grid, the most
    for most in [None, *grid_blocks]:
        if most is not None:
            device._blocks.update({k: min(v, most) for k, v in chosen_blocks.items()})
        wall, seconds, iterations, simulated = _time_steps(device, steps, after_step)
        phases = ", ".join(f"{k} {1000 * v / steps:.2f} ms" for k, v in seconds.items())
        grids = ", ".join(f"{k} {v}" for k, v in getattr(device, "_blocks", {}).items())
        print(
            f"{case} GPU ({scene.fluid.solver}, {scene.fluid.matrix_precision}): {fluid} "
            f"fluid + {len(device.kind) - fluid} wall/dummy particles (set-up and first step "
            f"{first:.1f} s); {steps / wall:.1f} steps/s, {fluid * steps / wall:.3g} "
            f"particle-steps/s, {wall / simulated:.1f} s per simulated second (dt "
            f"{simulated / steps:.3g} s); CG iterations {np.mean(iterations):.0f} (mean); per "
            f"step: {phases}; neighbour-list width {device.width}; blocks: {grids}"
            + ("" if probes is None else f"; {len(probes.pressure_names)} pressure probes read"),
            flush=True,
        )
    if probes is not None:  # heights now, pressures the mean over the timed steps
        probes.end_frame()
        print(
            f"{case} probes at t = {device.time:.4f} s: "
            + ", ".join(f"{k} {np.round(v, 4)}" for k, v in probes.frame_values().items()),
            flush=True,
        )
    return fluid


def _time_cpu(
    case: str, preset: str, overrides: dict[str, object], threads: int, steps: int
) -> None:
    """Times the CPU path of ``case`` on ``threads`` threads and prints it."""
    numba.set_num_threads(threads)
    cpu_scene = jellysim.load_scene(preset, overrides)
    cpu = FluidSimulation(cpu_scene).solver
    fluid = int(np.sum(cpu.kind == FLUID))
    cpu.step(cpu.stable_dt())  # compile, or load from Numba's cache
    steps = min(steps, 10)
    wall, _, iterations, simulated = _time_steps(cpu, steps)
    print(
        f"{case} CPU, {threads} threads: {steps / wall:.2f} steps/s, "
        f"{fluid * steps / wall:.3g} particle-steps/s, {wall / simulated:.1f} s per simulated "
        f"second; {cpu_scene.fluid.solver} iterations {np.mean(iterations):.0f}",
        flush=True,
    )


def _compare(case: str, preset: str, overrides: dict[str, object], steps: int) -> None:
    """Steps the CPU and GPU paths, each with the preset's pressure solver, ``steps`` times
    with the CPU's dt and prints how far apart their fluid particles are."""
    cpu = FluidSimulation(jellysim.load_scene(preset, overrides)).solver
    on_gpu = jellysim.load_scene(preset, {**overrides, "fluid.device": "cuda"})
    device = FluidSimulation(on_gpu).solver
    rows = cpu.kind == FLUID
    for _ in range(steps):
        dt = cpu.stable_dt()
        cpu.step(dt)
        device.step(dt)
    apart = np.abs(cpu.position[rows] - device.position[rows]).max()
    speed = np.abs(cpu.velocity[rows]).max()
    print(
        f"{case}: after {steps} steps (t = {cpu.time:.4f} s, the preset's "
        f"{cpu.params.solver}) the paths' fluid "
        f"particles are at most {apart:.3g} m = {apart / cpu.params.l0:.3g} l0 apart "
        f"(largest speed {speed:.3g} m/s, velocities at most "
        f"{np.abs(cpu.velocity[rows] - device.velocity[rows]).max():.3g} m/s apart)",
        flush=True,
    )


if __name__ == "__main__":
    main()
