"""The 2-D dam break side by side: jellysim's MPS against PySPH 1.0b2's WCSPH (issue 5).

    .venv/bin/python benchmarks/bench_pysph.py [--per-width 40 ...] [--threads 2]
        [--scheme wcsph ...] [--no-mps | --no-pysph] [--solver iccg|deflated]
        [--pysph .venv-pysph/bin/python] [--set KEY=VALUE ...] [--save RUNS.json]
    # --pysph: the venv of benchmarks/pysph_env.sh

Martin & Moyce's n^2 = 2 column (width a, height 2a) collapsing, at N particles across a, to
T = t sqrt(2 g / a) = 3.3, both codes on the same number of threads, one after the other:

- jellysim: the dam-break-2d preset (a = 0.1 m, a 5a tank; since 2026-11-24 the hexagonal
  lattice with the mixed source, the corrected gradient and the either-density surface, since
  2026-11-25 with collisions at 0.8 l0 and the surface repulsion; the paper's scheme is
  ``--set fluid.lattice=square --set fluid.source=standard --set fluid.gradient=standard
  --set fluid.surface=standard --set fluid.collision_distance=0.5
  --set fluid.surface_repulsion=false``) at fluid.spacing = a / N (and the pressure solver
  ``--solver``, the preset's ICCG by default), stepped by the solver at its own stable dt; the
  surge front recorded after every step.
- PySPH: its example dam_break_2d (a = 1 m; in a 5a tank, like jellysim's, since 2026-11-25: the
  example's 4a tank caps its front at T = 2.93; WCSPH with its adaptive step) at
  dx = a / N, run in PySPH's own venv by benchmarks/pysph_dam_break.py; the front at 200
  outputs. Its column is N x 2N particles, a x 2a like jellysim's, since 2026-11-25
  (``--pysph-block example``: the example's own N + 1 x 2N + 1, a column one spacing wider
  and taller, whose front leads by about 1/N of a).

Both fronts are measured the same way (jellysim.reference: the largest x of fluid particles
within 0.1 a of the floor, from the wall's inner face, over a) and compared with Martin & Moyce
for T <= 3, raw and after the best time shift of at most 0.3. Times are the wall time of the
stepping (jellysim after one compiling step, PySPH after its set-up, which compiles its code).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np
from _input import run_main  # benchmarks/: bad input in one line, exit 2

import jellysim
from jellysim.config.load import parse_override
from jellysim.fluid.geometry import FLUID
from jellysim.reference import front_errors, surge_front
from jellysim.simulation.fluid import FluidSimulation

HERE = Path(__file__).resolve().parent
UNTIL = 3.3


def run_mps(
    per_width: int, solver_name: str | None = None, sets: list[str] | None = None
) -> dict[str, object]:
    overrides: dict[str, object] = {"fluid.spacing": 0.1 / per_width}
    if solver_name:
        overrides["fluid.solver"] = solver_name
    for item in sets or []:
        key, value = parse_override(item)
        overrides[key] = value
    scene = jellysim.load_scene("dam-break-2d", overrides)
    solver = FluidSimulation(scene).solver
    a = scene.fluid.water_width
    scale = math.sqrt(2 * 9.81 / a)
    fluid = solver.kind == FLUID
    times = [0.0]
    fronts = [float(surge_front(solver.position[None], solver.alive[None], fluid, a)[0])]
    probe_dt = min(solver.stable_dt(), 1e-6)
    warm = FluidSimulation(scene).solver
    warm.step(probe_dt)  # compile or load from the cache, untimed
    steps = 0
    start = time.perf_counter()
    while solver.time * scale < UNTIL:
        solver.step(solver.stable_dt())
        steps += 1
        times.append(solver.time * scale)
        fronts.append(float(surge_front(solver.position[None], solver.alive[None], fluid, a)[0]))
        if steps % 250 == 0:  # progress, to stderr: the finest runs take most of an hour
            print(
                f"  MPS {per_width} across: step {steps}, T = {times[-1]:.3f}, front "
                f"{fronts[-1]:.3f} a, dt {times[-1] - times[-2]:.2e} in T, "
                f"{time.perf_counter() - start:.0f} s",
                file=sys.stderr, flush=True,
            )  # fmt: skip
    seconds = time.perf_counter() - start
    return {
        "seconds": seconds,
        "steps": steps,
        "fluid": int(fluid.sum()),
        "times": times,
        "fronts": fronts,
    }


def run_pysph(
    python: str, per_width: int, threads: int, scheme: str, block: str = "exact"
) -> dict[str, object] | str:
    """PySPH's result, or why it has none (a scheme that does not finish is reported, not
    fatal: PySPH 1.0b2's WCSPH crashes at 80 particles across a)."""
    with tempfile.TemporaryDirectory() as out:
        command = [
            python, str(HERE / "pysph_dam_break.py"), "--per-width", str(per_width),
            "--until", str(UNTIL), "--threads", str(threads), "--scheme", scheme, "--out", out,
            "--block", block,
        ]  # fmt: skip
        env = {**os.environ, "OMP_NUM_THREADS": str(threads)}
        clock = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True, env=env, check=False)
        seconds = time.perf_counter() - clock
    if done.returncode != 0:
        reason = done.stderr.strip().splitlines()[-1:] or [f"exit status {done.returncode}"]
        return f"did not finish: exit status {done.returncode} after {seconds:.0f} s ({reason[0]})"
    last = [line for line in done.stdout.splitlines() if line.startswith("{")][-1]
    result: dict[str, object] = json.loads(last)
    return result


def describe(name: str, run: dict[str, object] | str) -> str:
    if isinstance(run, str):
        return f"| {name} | {run} | | | | | |"
    times = np.asarray(run["times"])
    fronts = np.asarray(run["fronts"])
    raw, shifted, shift = front_errors(times, fronts, until=3.0)
    seconds = float(run["seconds"])  # type: ignore[arg-type]
    steps = int(run["steps"])  # type: ignore[call-overload]
    return (
        f"| {name} | {run['fluid']} | {steps} | {seconds:.1f} | {steps / seconds:.0f} | "
        f"{100 * raw:.1f} % | {100 * shifted:.1f} % ({shift:+.2f}) |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--per-width", type=int, action="append")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--scheme", action="append", help="PySPH scheme(s); default wcsph")
    parser.add_argument("--no-mps", action="store_true", help="run PySPH only")
    parser.add_argument("--no-pysph", action="store_true", help="run jellysim only")
    parser.add_argument("--solver", choices=("iccg", "cg", "deflated"), help="MPS PPE solver")
    parser.add_argument("--pysph", default=str(HERE.parent / ".venv-pysph" / "bin" / "python"))
    parser.add_argument(
        "--pysph-block", choices=("exact", "example"), default="exact",
        help="PySPH's column: N x 2N particles, a x 2a like jellysim's (exact), or its example's "
        "N + 1 x 2N + 1, (a + dx) x (2a + dx)",
    )  # fmt: skip
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE",
        help="a scene override for jellysim, e.g. fluid.lattice=square",
    )  # fmt: skip
    parser.add_argument(
        "--save", type=Path, metavar="RUNS.json",
        help="also write every run's front curve (T, x/a) and timing to this JSON file",
    )  # fmt: skip
    args = parser.parse_args()
    if not args.no_pysph and not Path(args.pysph).exists():
        sys.exit(f"no PySPH Python at {args.pysph}: build it with benchmarks/pysph_env.sh")
    numba.set_num_threads(args.threads)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores; numba {numba.__version__}; "
        f"{args.threads} threads each; to T = {UNTIL}"
    )
    print("| code, particles across a | fluid particles | steps | wall s | steps/s | "
          "front error, raw | shifted (shift) |")  # fmt: skip
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    saved: dict[str, dict[str, object] | str] = {}

    def report(name: str, run: dict[str, object] | str) -> None:
        print(describe(name, run), flush=True)
        saved[name] = run
        if args.save:
            args.save.write_text(json.dumps(saved) + "\n")

    for per_width in args.per_width or [40]:
        if not args.no_mps:
            name = f"jellysim MPS ({args.solver or 'preset'}), {per_width}"
            report(name, run_mps(per_width, args.solver, args.set))
        for scheme in [] if args.no_pysph else args.scheme or ["wcsph"]:
            name = f"PySPH {scheme.upper()}, {per_width}"
            if args.pysph_block != "exact":
                name += f" ({args.pysph_block} block)"
            report(name, run_pysph(args.pysph, per_width, args.threads, scheme, args.pysph_block))


if __name__ == "__main__":
    run_main(main)
