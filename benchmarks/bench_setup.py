"""Set-up time of every preset: ``jellysim.Simulation(scene)``, the best of ``--repeats``.

    .venv/bin/python benchmarks/bench_setup.py [--repeats 3] [--preset NAME ...]

The set-up builds what a run needs before its first frame: lattices, the bell (its shell, springs,
margin sampling and skin), the solver's buffers and neighbour lists, the tentacles' chain model
and substep plan. Kernels are not compiled here (``prepare()`` does that, and is not timed).
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import jellysim


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--preset", action="append", default=[])
    args = parser.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores")
    for name in args.preset or jellysim.preset_names():
        scene = jellysim.load_scene(name)
        best = float("inf")
        for _ in range(args.repeats):
            start = time.perf_counter()
            simulation = jellysim.Simulation(scene)
            best = min(best, time.perf_counter() - start)
        print(f"{name}: {best:.3f} s  ({simulation.describe()})")


if __name__ == "__main__":
    main()
