"""Cost of the tentacles in the simulated water (issue 26): sampling the water at every tentacle
particle (Eq. S1) and giving the drag's reaction back to it (Eq. S2), beside one frame of MPS
steps, at the full ``moon-jelly``.

    .venv/bin/python benchmarks/bench_water_coupling.py [--repeats 5]

Sets up ``moon-jelly`` with ``flow.model = "fluid"`` and ``flow.two_way = true``, times
``solver_water_velocity_at`` and ``BellInFluid.take_reaction`` on the tentacles' points (mean of
the repeats; the reaction with random impulses of the drag's order), then one ``step_frame`` (the
frame's MPS steps, the sampling and the reaction included), and prints the shares.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

import jellysim
from jellysim.coupling.water_at import solver_water_velocity_at


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    overrides = {"flow.model": "fluid", "flow.two_way": True, "duration": 0.1}
    simulation = jellysim.Simulation(jellysim.load_scene("moon-jelly", overrides))
    simulation.prepare()
    coupling = simulation.coupling  # type: ignore[attr-defined]
    solver = coupling.solver
    groups = simulation.tentacles.groups  # type: ignore[attr-defined]
    points = np.concatenate([g.positions.reshape(-1, 3) for g in groups])
    impulses = np.random.default_rng(1).standard_normal(points.shape) * 1e-4
    start = time.perf_counter()
    for _ in range(args.repeats):
        solver_water_velocity_at(solver, points)
    sampling = (time.perf_counter() - start) / args.repeats
    start = time.perf_counter()
    for _ in range(args.repeats):
        coupling.take_reaction(points, impulses, simulation.frame_dt)
    reaction = (time.perf_counter() - start) / args.repeats
    start = time.perf_counter()
    simulation.step_frame()
    frame = time.perf_counter() - start
    steps = int(coupling.stats.as_array()[0])
    both = sampling + reaction
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; "
        f"{len(solver.position)} particles, {len(points)} tentacle points\n"
        f"sampling {1e3 * sampling:.1f} ms, reaction {1e3 * reaction:.1f} ms a frame; "
        f"frame {frame:.2f} s in {steps} MPS steps ({frame / steps:.2f} s a step): "
        f"{100 * both / (frame / steps):.1f} % of a step, {100 * both / frame:.2f} % of the frame"
    )


if __name__ == "__main__":
    main()
