"""Set-up time of every preset: ``jellysim.Simulation(scene)``, the first in the process and the
best of ``--repeats``.

    .venv/bin/python benchmarks/bench_setup.py [--repeats 3] [--preset NAME ...]

The set-up builds what a run needs before its first frame: lattices, the bell (its shell, springs,
margin sampling and skin), the solver's buffers and neighbour lists, the tentacles' chain model
and substep plan. Kernels are not compiled here (``prepare()`` does that, and is not timed). The
first set-up of the process also pays the imports it triggers (SciPy's spatial trees, say): that is
what ``jellysim run`` pays; run one preset per process (``--preset NAME``) to see it per preset.
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
        seconds = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            simulation = jellysim.Simulation(scene)
            seconds.append(time.perf_counter() - start)
        print(
            f"{name}: first {seconds[0]:.3f} s, best {min(seconds):.3f} s  "
            f"({simulation.describe()})"
        )


if __name__ == "__main__":
    main()
