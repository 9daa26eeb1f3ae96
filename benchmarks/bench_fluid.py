"""MPS speed: steps per second and the time per phase at about 57,000 fluid particles.

    .venv/bin/python benchmarks/bench_fluid.py [--steps 20] [--threads N] [--chunksize N]
        [--solver NAME]
        [--case NAME ...] [--set KEY=VALUE ...] [--compare-solvers] [--compare-precision R]

The dam break of dam-break-2d at a / l0 = 158 with the preset's own scheme (hexagonal lattice,
mixed source, corrected gradient: 57,670 fluid particles), the same dam break with the paper's
standard scheme on the square lattice at a / l0 = 170 (57,800; the series of docs/performance.md
before 2026-11-24), and the 3-D tank of tank-3d at a / l0 = 30 (54,000 fluid particles), each
from rest, at the presets' defaults (r_e 2.1 / 4.0 l0 in 2-D, 2.1 / 3.1 l0 in 3-D; the pressure
solver to a relative residual of 1e-8: the preset's, or ``--solver`` (iccg, cg, deflated) for
every case; Courant 0.2).
One step is taken first (JIT compilation or cache load, not timed); then ``--steps`` steps at the
solver's stable dt are timed. Walls and dummy particles are not counted.

``--compare-solvers``: after the timed steps, the PPE at the current positions (close to the
next step's; ``compare_solvers``) is solved from a cold
start (zero pressure) by plain CG, ICCG and deflated CG to the scene's tolerance, and each
one's iterations and wall time are printed (issue 5: a preconditioned CG at least 3x fewer
iterations than plain CG).

``--compare-precision R``: the same PPE assembled with the matrix in double and in single
precision (``fluid.matrix_precision``), each solved from zero by the scene's solver R times, the
two in turn, and ten products with A each time; the medians are printed.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import time

import numba
import numpy as np
from _input import run_main  # benchmarks/: bad input in one line, exit 2

import jellysim
from jellysim.config.load import parse_override
from jellysim.fluid.geometry import FLUID
from jellysim.fluid.mps import MPSSolver
from jellysim.fluid.solvers import CoarseSpace, solve
from jellysim.simulation.fluid import FluidSimulation

CASES: dict[str, tuple[str, dict[str, object]]] = {
    # name: (preset, overrides)
    "dam-break-2d": ("dam-break-2d", {"fluid.spacing": 0.1 / 158}),
    "dam-break-2d-square": (
        "dam-break-2d",
        {
            "fluid.spacing": 0.1 / 170,
            "fluid.lattice": "square",
            "fluid.source": "standard",
            "fluid.gradient": "standard",
            "fluid.surface": "standard",
        },
    ),
    "tank-3d": ("tank-3d", {"fluid.spacing": 0.1 / 30}),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--threads", type=int, default=numba.config.NUMBA_NUM_THREADS)
    parser.add_argument(
        "--chunksize", type=int, default=0,
        help="iterations a chunk of every parallel loop (numba.set_parallel_chunksize; 0, "
        "Numba's default: the loop split evenly between the threads once); the same bits",
    )  # fmt: skip
    parser.add_argument("--case", choices=tuple(CASES), action="append")
    parser.add_argument("--solver", choices=("iccg", "cg", "deflated"))
    parser.add_argument("--compare-solvers", action="store_true")
    parser.add_argument(
        "--compare-precision", type=int, default=0, metavar="R",
        help="after the timed steps, the next PPE assembled with its matrix in double and in "
        "single precision, each solved from zero by the scene's solver R times, alternately",
    )  # fmt: skip
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE",
        help="a scene override for every case, e.g. fluid.neighbour_skin=0.6",
    )  # fmt: skip
    args = parser.parse_args()
    numba.set_num_threads(args.threads)
    numba.set_parallel_chunksize(args.chunksize)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores; numba {numba.__version__}, "
        f"threads {numba.get_num_threads()}, chunk size {args.chunksize}"
    )
    for name in args.case or list(CASES):
        preset, defaults = CASES[name]
        overrides = dict(defaults)
        if args.solver:
            overrides["fluid.solver"] = args.solver
        for item in args.set:
            key, value = parse_override(item)
            overrides[key] = value
        scene = jellysim.load_scene(preset, overrides)
        simulation = FluidSimulation(scene)
        solver = simulation.solver
        fluid = int(np.sum(solver.kind == FLUID))
        solver.step(solver.stable_dt())  # compile or load from the cache
        searches, started = solver.searches, solver.time
        seconds: dict[str, float] = {}
        iterations = []
        start = time.perf_counter()
        for _ in range(args.steps):
            stats = solver.step(solver.stable_dt())
            iterations.append(stats.iterations)
            for phase, value in stats.seconds.items():
                seconds[phase] = seconds.get(phase, 0.0) + value
        wall = time.perf_counter() - start
        phases = ", ".join(f"{k} {1000 * v / args.steps:.0f} ms" for k, v in seconds.items())
        print(
            f"{name}: {fluid} fluid + {len(solver.kind) - fluid} wall/dummy particles; "
            f"{args.steps / wall:.2f} steps/s; {scene.fluid.solver} iterations "
            f"{np.mean(iterations):.0f} "
            f"(mean); per step: {phases}; {solver.searches - searches} cell searches "
            f"(neighbour_skin {scene.fluid.neighbour_skin:g} l0) over "
            f"t = {started:.4f}-{solver.time:.4f} s; threading layer {numba.threading_layer()}"
        )
        if args.compare_solvers:
            compare_solvers(solver)
        if args.compare_precision > 0:
            compare_precision(solver, args.compare_precision)


def compare_solvers(solver: MPSSolver) -> None:
    """Iterations and wall time of each PPE solver, from zero, on the PPE at the current
    positions taken as r* (no explicit stage; the mixed source's n^k is the last step's start,
    and the either-density surface tests n* alone): close to the next step's PPE."""
    p = solver.params
    # Assembled as for ICCG (sorted columns, which IC(0) needs; the others take any order).
    solver.params = dataclasses.replace(p, solver="iccg")
    system = solver.poisson_system(solver.stable_dt())
    solver.params = p
    coarse = CoarseSpace(solver.position[system.particles], solver.domain_min, p.coarse_cell * p.l0)
    counts = {}
    for method in ("cg", "iccg", "deflated"):
        solve(system.matrix, system.rhs, np.zeros_like(system.rhs), method, p.tolerance, 10_000,
              coarse)  # fmt: skip
        clock = time.perf_counter()
        counts[method], residual, _ = solve(
            system.matrix, system.rhs, np.zeros_like(system.rhs), method, p.tolerance, 10_000,
            coarse,
        )  # fmt: skip
        seconds = time.perf_counter() - clock
        print(
            f"  PPE of {system.rhs.size} rows, cold start: {method} {counts[method]} iterations "
            f"to {residual:.1e} in {1000 * seconds:.0f} ms"
        )
    print(
        f"  fewer iterations than CG: ICCG {counts['cg'] / counts['iccg']:.1f}x, deflated "
        f"{counts['cg'] / counts['deflated']:.1f}x"
    )


def compare_precision(solver: MPSSolver, repeats: int) -> None:
    """The PPE at the current positions (as :func:`compare_solvers`) assembled with the matrix
    in double and in single precision (fluid.matrix_precision), each solved from zero by the
    scene's solver ``repeats`` times, the two in turn (so that a busy moment of the machine
    falls on both); prints the median wall time of a solve and of a product with A."""
    p = solver.params
    dt = solver.stable_dt()
    systems = {}
    for precision in ("double", "single"):
        solver.params = dataclasses.replace(p, matrix_precision=precision)
        systems[precision] = solver.poisson_system(dt)
    solver.params = p
    coarse = CoarseSpace(
        solver.position[systems["double"].particles], solver.domain_min, p.coarse_cell * p.l0
    )
    seconds: dict[str, list[float]] = {"double": [], "single": []}
    products: dict[str, list[float]] = {"double": [], "single": []}
    counts = {}
    for _ in range(repeats + 1):  # the first of each compiles, or loads from the cache
        for precision, system in systems.items():
            x = np.zeros_like(system.rhs)
            clock = time.perf_counter()
            counts[precision], _, _ = solve(
                system.matrix, system.rhs, x, p.solver, p.tolerance, 10_000, coarse
            )
            seconds[precision].append(time.perf_counter() - clock)
            out = np.empty_like(x)
            clock = time.perf_counter()
            for _ in range(10):
                system.matrix.apply(x, out)
            products[precision].append((time.perf_counter() - clock) / 10)
    for precision in systems:
        print(
            f"  PPE of {systems[precision].rhs.size} rows, matrix in {precision}: "
            f"{p.solver} {counts[precision]} iterations from zero, median "
            f"{1000 * np.median(seconds[precision][1:]):.1f} ms a solve, "
            f"{1000 * np.median(products[precision][1:]):.2f} ms a product with A "
            f"({repeats} of each)"
        )


if __name__ == "__main__":
    run_main(main)
