"""PySPH's own 2-D dam break, run for benchmarks/bench_pysph.py inside the PySPH venv.

    VENV/bin/python benchmarks/pysph_dam_break.py --per-width N --until T --threads K --out DIR

Runs `pysph.examples.dam_break_2d` (Martin & Moyce's n^2 = 2 column, a = 1 m) with the scheme
named by ``--scheme`` (default wcsph, PySPH's fastest for it) at dx = a / N, to
T = t sqrt(2 g / a) = ``--until``. Four changes to the example, which are what a resolution
study against jellysim needs and change nothing else: its particles take the module-level h and
mass of the default dx = 0.03 whatever ``--dx`` says, so they are reset from dx here; the final
time is set from T; the tank is ``--tank`` a long (default 5, jellysim's preset) instead of
the example's 4: in a 4a tank the front reaches the far wall at T = 2.93, before the last point
of the comparison (T = 2.98), which caps PySPH's front there and flatters its raw error; and the
column is N x 2N particles (``--block exact``, the default), a x 2a like jellysim's, where the
example's block has N + 1 x 2N + 1 (both ends of [0, a] and [0, 2a] included, ``--block
example``): with each particle's area dx^2 that column is (a + dx) x (2a + dx), 1/N wider and
1/(2N) taller than a, and its front, measured over a, leads by about 1/N of a from the start. The
set-up (which compiles PySPH's generated code) is not timed; the solve is. Prints one JSON line:
wall seconds, steps, fluid particles, and the surge front (the largest x of fluid particles
within 0.1 a of the floor, measured from the wall's inner face, over a) at every output. This
file imports only PySPH (its venv has NumPy 1.26; jellysim's has 2.x).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import numpy as np
import pysph.examples.dam_break_2d as example
from pysph.solver.utils import iter_output

WIDTH = example.fluid_column_width  # a = 1 m
build_tank = example.get_2d_tank
build_block = example.get_2d_block


def exact_block(dx, length, height, center):  # type: ignore[no-untyped-def]
    """round(length / dx) x round(height / dx) particles dx apart, the first at the block's
    lower-left corner (the example then moves the block by dx along both axes): a column whose
    particles' squares of side dx fill exactly length x height, like jellysim's."""
    nx, ny = round(length / dx), round(height / dx)
    x, y = np.meshgrid(np.arange(nx) * dx, np.arange(ny) * dx, indexing="ij")
    return x.ravel() + center[0] - length / 2, y.ravel() + center[1] - height / 2


class DamBreak(example.DamBreak2D):
    tank = 5.0  # in units of a; the inner left wall stays at x = 0
    block = "exact"  # N x 2N particles (a x 2a), or "example": N + 1 x 2N + 1

    def create_particles(self):  # type: ignore[no-untyped-def]
        # The example builds its particle arrays from the module's h and m (for dx = 0.03),
        # and its tank from a module-level function called with a fixed length and centre.
        example.h = self.h
        example.m = self.dx**2 * example.ro
        length = self.tank * WIDTH

        def tank(**kwargs):  # type: ignore[no-untyped-def]
            kwargs.update(length=length, base_center=[length / 2, 0.0])
            return build_tank(**kwargs)

        example.get_2d_tank = tank
        example.get_2d_block = exact_block if self.block == "exact" else build_block
        return super().create_particles()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--per-width", type=int, required=True)
    parser.add_argument("--until", type=float, default=3.3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--scheme", default="wcsph")
    parser.add_argument("--outputs", type=int, default=200)
    parser.add_argument("--tank", type=float, default=5.0, help="tank length in a (example: 4)")
    parser.add_argument(
        "--block", choices=("exact", "example"), default="exact",
        help="the column: N x 2N particles, a x 2a (exact), or the example's N + 1 x 2N + 1",
    )  # fmt: skip
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    os.environ["OMP_NUM_THREADS"] = str(args.threads)
    dx = WIDTH / args.per_width
    final = args.until / math.sqrt(2.0 * example.g / WIDTH)
    # WCSPH's first step is 0.125 h / c0; the adaptive step stays near it in this case.
    steps = final / (0.125 * example.hdx * dx / example.co)
    DamBreak.tank = args.tank
    DamBreak.block = args.block
    app = DamBreak(fname="dam_break_2d")
    app.setup(
        [
            "--scheme", args.scheme, "--dx", repr(dx), "--tf", repr(final), "--openmp",
            "--pfreq", str(max(1, int(steps / args.outputs))), "-d", args.out, "-q",
        ]
    )  # fmt: skip
    start = time.perf_counter()
    app.solve()
    seconds = time.perf_counter() - start
    files = sorted(app.output_files, key=lambda name: int(name.rsplit("_", 1)[1].split(".")[0]))
    times, fronts, first = [], [], None
    for info, fluid in iter_output(files, "fluid"):
        x, y = fluid.get("x"), fluid.get("y")
        if first is None:  # the inner faces: half a spacing outside the first particles
            first = (x.min() - dx / 2, y.min() - dx / 2, x.size)
        near = y - first[1] < 0.1 * WIDTH
        times.append(info["t"] * math.sqrt(2.0 * example.g / WIDTH))
        fronts.append(float((x[near].max() - first[0]) / WIDTH))
    print(
        json.dumps(
            {
                "seconds": seconds,
                "steps": int(app.solver.count),
                "fluid": int(first[2]) if first else 0,
                "times": times,
                "fronts": fronts,
            }
        )
    )


if __name__ == "__main__":
    main()
