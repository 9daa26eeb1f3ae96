"""The ICCG solve of one PPE by parts: IC(0) factorization, compaction, the compiled CG and one
preconditioner application, each the best of ``--repeats``.

    .venv/bin/python benchmarks/bench_iccg.py [--case tank-3d|dam-break-2d] [--repeats 5]
        [--threads 2]

The PPE is the one of bench_fluid.py's case after one step (tank-3d at a / l0 = 30, 57,606
rows; the dam break at a / l0 = 158, 57,671 rows), assembled for ICCG, solved from zero to a
relative residual of 1e-8. Best-of-N separates the solver's own cost from a shared host's
scatter, which single timings (``bench_fluid.py --compare-solvers``) do not.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numba
import numpy as np

import jellysim
from jellysim.fluid import linalg
from jellysim.simulation.fluid import FluidSimulation

CASES: dict[str, tuple[str, dict[str, object]]] = {
    "tank-3d": ("tank-3d", {"fluid.spacing": 0.1 / 30}),
    "dam-break-2d": ("dam-break-2d", {"fluid.spacing": 0.1 / 158}),
}


def best(repeats: int, work: Callable[[], Any]) -> tuple[float, Any]:
    """The shortest wall time (s) of ``repeats`` calls, and the last call's answer."""
    shortest, answer = float("inf"), None
    for _ in range(repeats):
        start = time.perf_counter()
        answer = work()
        shortest = min(shortest, time.perf_counter() - start)
    return shortest, answer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--case", choices=tuple(CASES), default="tank-3d")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=numba.config.NUMBA_NUM_THREADS)
    args = parser.parse_args()
    numba.set_num_threads(args.threads)
    preset, overrides = CASES[args.case]
    solver = FluidSimulation(jellysim.load_scene(preset, overrides)).solver
    solver.step(solver.stable_dt())
    solver.params = dataclasses.replace(solver.params, solver="iccg")
    system = solver.poisson_system(solver.stable_dt())
    matrix, rhs = system.matrix, system.rhs
    factor = np.zeros(matrix.data.shape)  # L in double, as the solver's
    linalg.incomplete_cholesky(matrix, 0.0, factor)  # compile or load from the cache
    factorize, _ = best(args.repeats, lambda: linalg.incomplete_cholesky(matrix, 0.0, factor))
    compact, compacted = best(args.repeats, lambda: linalg.compact_factor(matrix, factor))
    tolerance = 1e-8

    def cg() -> tuple[int, float]:
        return linalg.conjugate_gradient(
            matrix, compacted, rhs, np.zeros_like(rhs), tolerance, 10_000
        )

    cg()
    solve, (iterations, residual) = best(args.repeats, cg)
    z = np.empty_like(rhs)
    once, _ = best(4 * args.repeats, lambda: compacted.precondition(rhs, z))
    print(
        f"{args.case}: {rhs.size} rows, threads {numba.get_num_threads()}; IC(0) "
        f"{1e3 * factorize:.1f} ms, compaction {1e3 * compact:.1f} ms, CG {1e3 * solve:.1f} ms "
        f"({iterations} iterations to {residual:.1e}), one preconditioner application "
        f"{1e3 * once:.2f} ms"
    )


if __name__ == "__main__":
    main()
