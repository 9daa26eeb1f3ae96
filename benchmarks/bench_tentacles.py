"""Tentacle throughput: brown-jelly as the paper's Case 1 (10 s simulated) at several Young's
moduli.

    .venv/bin/python benchmarks/bench_tentacles.py [--threads N]

Reports, per modulus, the substep, the wall time of the whole run with output on (result.h5
written frame by frame, checkpoints included; start-up and JIT compilation excluded) and the
particle-steps per second. JIT compilation (first call in a fresh cache) is timed apart. The
preset runs with the paper's Case 1 values (``PAPER_CASE_1``: 60 straight particles in a
0.3 m/s flow, the preset's defaults before issue 25), so that the figures in
docs/performance.md stay comparable across versions.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time

import numba

import jellysim
from jellysim.simulation import Simulation

MODULI = (1e2, 2.4e5, 5e6, 9e9)
# The paper's Case 1 (the preset file's note): brown-jelly's defaults swim slower, with longer,
# curled tentacles and four oral arms (issue 25); the paper's six tentacles are its marginal group,
# alone (case_1_scene).
PAPER_CASE_1: dict[str, object] = {
    "flow.speed": 0.3,
    "bell.swim_speed": 0.3,
    "tentacles.particles": 60,
    "tentacles.rest_curvature": 0.0,
    "tentacles.rest_curvature_tip": 0.0,
}


def case_1_scene(overrides: dict[str, object]) -> jellysim.Scene:
    """brown-jelly's marginal group alone (the paper's six tentacles, no oral arms) as a
    one-table scene, with ``overrides`` (one-table keys, ``tentacles.KEY``)."""
    return jellysim.load_scene(jellysim.load_scene("brown-jelly").group_scene(0), overrides)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--threads", type=int, default=numba.config.NUMBA_NUM_THREADS)
    parser.add_argument("--duration", type=float, default=10.0)
    args = parser.parse_args()
    numba.set_num_threads(args.threads)
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
        f"numba {numba.__version__}, threads {numba.get_num_threads()}"
    )

    start = time.perf_counter()
    warm = Simulation(case_1_scene({**PAPER_CASE_1, "duration": 0.1}))
    warm.step_frame()
    print(f"first frame incl. JIT compile or cache load: {time.perf_counter() - start:.2f} s")

    print(f"{'E [Pa]':>10} {'dt [s]':>10} {'substeps':>9} {'wall [s]':>9} {'particle-steps/s':>17}")
    for modulus in MODULI:
        scene = case_1_scene(
            {**PAPER_CASE_1, "tentacles.youngs_modulus": modulus, "duration": args.duration}
        )
        with tempfile.TemporaryDirectory() as folder:
            start = time.perf_counter()
            result = jellysim.run(scene, folder, quiet=True)
            wall = time.perf_counter() - start
            substeps = int(result.file.attrs["tentacle_substeps"])
            dt = float(result.file.attrs["tentacle_dt"])
            result.close()
        t = scene.tentacles
        work = t.count * t.particles * substeps * (scene.frame_count - 1)
        print(f"{modulus:>10.3g} {dt:>10.3g} {substeps:>9d} {wall:>9.3f} {work / wall:>17.3g}")


if __name__ == "__main__":
    main()
