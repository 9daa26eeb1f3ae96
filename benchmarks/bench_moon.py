"""The moon-jelly preset (issue 6): wall time for three pulses, per phase.

    .venv/bin/python benchmarks/bench_moon.py [--seconds 0.5 | --steps N] [--threads N]
        [--preset NAME] [--set KEY=VALUE ...] [--from-frame F [--state FOLDER]]

The preset (``--preset``, default moon-jelly; moon-jelly-weightless for the paper's weightless
set-up) at its own resolution (l0 = 0.16 m: 56,524 water and 1,076 bell particles, 10 tentacles)
is set up (its time reported: lattice, bell, springs, margin, skin, solver) and simulated for
``--seconds`` of simulated time after the kernels are compiled or loaded from
the cache (not timed), and the wall time of every phase is reported per MPS step: the fluid's
phases (neighbours, explicit, PPE assembly, solve, correction), the springs, the tentacles and
the rest (margin records, bookkeeping). ``--seconds`` equal to three periods measures the whole
target. With explicit springs (``--set bell.spring_integration=explicit``) in weightless water a
shorter run projects it: dt is the springs' fixed limit (``bell_spring_dt``) as long as the
fluid's Courant limit is longer, so the steps of three pulses are known exactly, and the
projection is steps x the measured cost of a step (stated as such). The preset's implicit
springs leave dt to the fluid: in weightless water its Courant limit, which follows the flow, so
only the whole run counts; under gravity (moon-jelly) a fixed bound, kappa sqrt(l0 / g), tighter
than the springs' (12 steps a frame), but the step's cost grows as the run goes on, so again
only the whole run counts.
``--steps N`` takes N MPS steps of the water and the bell instead (no frame: the tentacles and
the margin's records are left out), for a preset whose frame takes many minutes on a CPU
(moon-jelly-fine: 1.5 million water particles, 20 steps a frame); the kernels' compilation on a
throw-away copy of the solver, a step's cost, is timed apart ("prepare"). The peak resident
memory of the process is reported at the end.
``--from-frame F`` times from frame F instead of from rest: the preset is simulated to it first
(not timed), so that the water has moved, which makes a step dearer (docs/performance.md, "Lists
at the near radius": at t = 2 s half as much again as at rest). With ``--state FOLDER`` the state
at frame F is kept there as a checkpoint (the format of ``jellysim run``'s): written by the first
run, read by every later one of the same scene and F, which then start at once.
Results are not written to disk.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import resource
import sys
import time
from pathlib import Path

import numba
import numpy as np
from _input import run_main  # benchmarks/: bad input in one line, exit 2

import jellysim
from jellysim.config import scene_to_toml
from jellysim.errors import InputError
from jellysim.io.checkpoint import CHECKPOINT_FILE, load_checkpoint, save_checkpoint


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=0.5)
    parser.add_argument("--steps", type=int, default=0)
    parser.add_argument("--threads", type=int, default=numba.config.NUMBA_NUM_THREADS)
    parser.add_argument("--preset", default="moon-jelly")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument(
        "--from-frame", type=int, default=0, metavar="F",
        help="time from frame F (simulated to it first, not timed) instead of from rest",
    )  # fmt: skip
    parser.add_argument(
        "--state", type=Path, metavar="FOLDER",
        help="with --from-frame: the folder that keeps the state at frame F (written by the "
        "first run, read by later ones)",
    )  # fmt: skip
    args = parser.parse_args()
    if args.from_frame < 0 or (args.state is not None and args.from_frame == 0):
        parser.error("--from-frame must be positive, and --state needs it")
    numba.set_num_threads(args.threads)
    scene = jellysim.load_scene(args.preset, args.set)  # VALUEs read as TOML, as by --set
    if args.from_frame >= scene.frame_count:  # frames 0 to frame_count - 1
        last = scene.frame_count - 1
        parser.error(f"--from-frame {args.from_frame}: {scene.name}'s last frame is {last}")
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores; numba {numba.__version__}, "
        f"threads {numba.get_num_threads()}"
    )
    start = time.perf_counter()
    simulation = jellysim.Simulation(scene)
    print(f"set-up: {time.perf_counter() - start:.2f} s")
    print(simulation.describe())
    start = time.perf_counter()
    simulation.prepare()
    print(f"prepare: {time.perf_counter() - start:.2f} s")
    if args.from_frame:
        advance(simulation, args.from_frame, args.state)  # another frame or scene: exit 2
    if args.steps:
        mps_steps(simulation, args.steps)
        return

    frames = max(1, round(args.seconds * scene.fps))
    steps = 0
    springs = tentacles = 0.0
    coupling = simulation.coupling
    bell = coupling.body
    implicit = bell.integration == "implicit"
    spring_force, tentacle_step = bell.step_force, simulation.tentacles.step_frame

    def timed_springs(*a: object) -> None:
        nonlocal springs
        start = time.perf_counter()
        spring_force(*a)  # type: ignore[arg-type]
        springs += time.perf_counter() - start

    def timed_tentacles() -> None:
        nonlocal tentacles
        start = time.perf_counter()
        tentacle_step()
        tentacles += time.perf_counter() - start

    bell.step_force = timed_springs  # type: ignore[method-assign]
    simulation.tentacles.step_frame = timed_tentacles  # type: ignore[method-assign]
    iterations = []
    start = time.perf_counter()
    for _ in range(frames):
        simulation.step_frame()
        steps += coupling.stats.steps
        iterations.append(coupling.stats.iterations)
    wall = time.perf_counter() - start

    fluid = sum(coupling.stats.seconds.values())
    phases = {**coupling.stats.seconds, "springs": springs, "tentacles": tentacles}
    phases["other"] = wall - fluid - springs - tentacles
    simulated = frames / scene.fps
    print(
        f"{simulated:g} s simulated in {wall:.1f} s: {steps} MPS steps "
        f"({steps / wall:.2f} steps/s), PPE iterations {np.mean(iterations):.0f} (mean, last step "
        f"of each frame)"
    )
    print("per step: " + ", ".join(f"{k} {1000 * v / steps:.0f} ms" for k, v in phases.items()))
    three = 3 * scene.bell.period
    if simulated >= three - 1e-9:
        print(f"three pulses ({three:g} s): {wall / 60:.1f} min measured")
    elif implicit or any(scene.water.gravity):
        print(
            "three pulses: not projected (the fluid's limits set the steps, and a step costs more "
            f"as the run goes on); run --seconds {three:g}"
        )
    else:
        dt = coupling.spring_dt
        per_frame = math.ceil((1.0 / scene.fps) / dt - 1e-9)
        needed = per_frame * round(three * scene.fps)
        print(
            f"three pulses ({three:g} s): {needed} steps of at most {dt:.4g} s "
            f"({per_frame} per frame); projected {needed * wall / steps / 60:.1f} min "
            f"at the measured {wall / steps:.2f} s per step"
        )


def advance(simulation: jellysim.Simulation, frame: int, state: Path | None) -> None:
    """Bring ``simulation`` to ``frame``: from the checkpoint in ``state`` when it holds that
    frame of this scene, else simulated (and then written there, when given)."""
    scene_toml = scene_to_toml(simulation.scene)
    if state is not None and (state / CHECKPOINT_FILE).is_file():
        saved, arrays = load_checkpoint(state, scene_toml)
        if saved != frame:
            raise InputError(
                f"{state / CHECKPOINT_FILE} holds frame {saved}, not {frame}: pass "
                f"--from-frame {saved}, or another folder"
            )
        simulation.restore(saved, arrays)
        print(f"frame {frame} (t = {simulation.time:g} s) read from {state / CHECKPOINT_FILE}")
        return
    start = time.perf_counter()
    while simulation.frame < frame:
        simulation.step_frame()
        print(f"  frame {simulation.frame} of {frame}", end="\r", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    print(
        f"frame {frame} (t = {simulation.time:g} s) simulated in "
        f"{time.perf_counter() - start:.1f} s (not timed)"
    )
    if state is not None:
        state.mkdir(parents=True, exist_ok=True)
        save_checkpoint(state, simulation.frame, scene_toml, simulation.checkpoint_state())
        print(f"kept in {state / CHECKPOINT_FILE}")


def mps_steps(simulation: jellysim.Simulation, count: int) -> None:
    """``count`` MPS steps of the water and the bell from the simulation's state (rest, or
    ``--from-frame``), each of the stable dt, timed one by one and by phase (the springs'
    among them), and the bell's and the water's largest displacement since the first.

    Each step is one call of the coupling's ``advance`` to a time a hair short of a whole
    stable step ahead: to ``time + dt`` itself, rounding can leave the remainder a hair longer
    than dt, which ``advance`` covers in two half steps (timed as one before 2026-11-29)."""
    coupling = simulation.coupling
    solver = coupling.solver
    frame_dt = 1.0 / simulation.scene.fps
    start_position = solver.position.copy()
    water = slice(0, coupling.water_particles)  # the MPS rows: water, bell, tank
    l0 = solver.params.l0
    for step in range(count):
        dt = min(solver.stable_dt(), coupling.spring_dt) * (1.0 - 1e-9)
        before = dict(coupling.stats.seconds)
        start = time.perf_counter()
        coupling.advance(solver.time + dt, frame_dt)
        wall = time.perf_counter() - start
        if coupling.stats.steps != 1:  # never: the remainder is shorter than the limit
            raise RuntimeError(f"advance took {coupling.stats.steps} steps, not one")
        phases = {k: v - before.get(k, 0.0) for k, v in coupling.stats.seconds.items()}
        moved = np.linalg.norm(solver.position - start_position, axis=1)
        print(
            f"step {step + 1}: dt {dt:.4g} s, {wall:.1f} s wall ("
            + ", ".join(f"{k} {v:.2f} s" for k, v in phases.items())
            + f"), PPE iterations {coupling.stats.iterations}, residual "
            f"{coupling.stats.residual:.2g}; largest move since the first step: bell "
            f"{moved[coupling.bell_rows].max() / l0:.2g} l0, "
            f"water {moved[water].max() / l0:.2g} l0",
            flush=True,
        )
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    print(f"peak resident memory: {peak:.2f} GiB")


if __name__ == "__main__":
    run_main(main)
