"""Throughput of the lions-mane preset: 600 tentacles of 60 particles in 8 clusters plus 4 oral
arms, two tentacle groups, each with its own substep (issue 25).

    .venv/bin/python benchmarks/bench_lions_mane.py [--threads N] [--duration S] [--repeats R]
        [--no-output] [--parts] [--set KEY=VALUE ...]

Each repeat runs ``jellysim.run("lions-mane", out=<temporary folder>)`` with output on
(result.h5 written with every frame, the bell's mesh included, checkpoints as the preset sets
them); with ``--no-output`` it steps a :class:`jellysim.Simulation` frame by frame instead and
writes nothing. Reported per repeat: the wall time (start-up and JIT compilation excluded; the
first, untimed frame compiles or loads the kernels), the CPU time of the process over the same span
(all its threads), the particle-steps per second (simulated particles x substeps, summed over the
groups, per wall second) and the load average at the end of the repeat; once, the frames and the
substeps per frame of each group. On a machine whose cores other work shares, the wall time
mostly measures that work; the CPU time does not. ``--parts`` adds one run without output that
splits a frame's time (wall and CPU, ms) between each group's compiled kernel and the Python
around it (roots, flow, rest-frame normals, watchdog). ``--set KEY=VALUE`` (repeatable) changes a
key of the preset as ``jellysim run --set`` does, e.g. ``--set bell.tentacle_contact=false``.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time

import numba
from _input import run_main  # benchmarks/: bad input in one line, exit 2

import jellysim
from jellysim.config.load import parse_override
from jellysim.simulation import Simulation, tentacles

SCENE = "lions-mane"


def particle_steps_per_frame(simulation: Simulation) -> int:
    """Simulated particles x substeps per frame, summed over the tentacle groups."""
    return sum(
        g.scene.tentacles.count * g.scene.tentacles.particles * g.plan.substeps
        for g in simulation.groups  # type: ignore[attr-defined]
    )


def timed_run(duration: float, output: bool, changes: dict[str, object]) -> tuple[float, float]:
    """Wall and CPU time (s) of one run of ``duration`` simulated seconds; with output, the
    whole of ``jellysim.run`` (scene set-up and writing included), without, the frame loop."""
    scene = jellysim.load_scene(SCENE, {**changes, "duration": duration})
    if output:
        with tempfile.TemporaryDirectory() as folder:
            start, cpu = time.perf_counter(), time.process_time()
            jellysim.run(scene, folder, quiet=True).close()
            return time.perf_counter() - start, time.process_time() - cpu
    simulation = Simulation(scene)
    simulation.prepare()
    start, cpu = time.perf_counter(), time.process_time()
    for _ in range(scene.frame_count - 1):
        simulation.step_frame()
    return time.perf_counter() - start, time.process_time() - cpu


def parts(duration: float, changes: dict[str, object]) -> None:
    """Print the mean wall and CPU time per frame (ms) of each group's kernel call and of the rest
    of ``step_frame``, over one run of ``duration`` simulated seconds without output."""
    scene = jellysim.load_scene(SCENE, {**changes, "duration": duration})
    simulation = Simulation(scene)
    simulation.prepare()
    names = {id(g.positions): g.name for g in simulation.groups}  # type: ignore[attr-defined]
    spent = {name: [0.0, 0.0] for name in names.values()}
    kernel = tentacles.advance_frame

    def timed_kernel(*args: object) -> None:
        start, cpu = time.perf_counter(), time.process_time()
        kernel(*args)
        total = spent[names[id(args[0])]]
        total[0] += time.perf_counter() - start
        total[1] += time.process_time() - cpu

    frames = scene.frame_count - 1
    tentacles.advance_frame = timed_kernel  # type: ignore[assignment]
    try:
        start, cpu = time.perf_counter(), time.process_time()
        for _ in range(frames):
            simulation.step_frame()
        wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    finally:
        tentacles.advance_frame = kernel  # type: ignore[assignment]
    rest = [wall - sum(t[0] for t in spent.values()), cpu - sum(t[1] for t in spent.values())]
    print(f"per frame, {frames} frames without output: {'wall [ms]':>10} {'CPU [ms]':>9}")
    for name, (w, c) in [*((f"kernel {n}", t) for n, t in spent.items()), ("rest", rest)]:
        print(f"  {name:<36} {1e3 * w / frames:>10.2f} {1e3 * c / frames:>9.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--threads", type=int, default=numba.config.NUMBA_NUM_THREADS)
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-output", action="store_true", help="step frames, write nothing")
    parser.add_argument("--parts", action="store_true", help="split a frame: kernels and Python")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    changes: dict[str, object] = dict(parse_override(item) for item in args.set)
    numba.set_num_threads(args.threads)

    start = time.perf_counter()
    warm = Simulation(jellysim.load_scene(SCENE, {**changes, "duration": 0.1}))
    warm.step_frame()
    print(f"first frame incl. JIT compile or cache load: {time.perf_counter() - start:.2f} s")
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
        f"numba {numba.__version__}, threads {numba.get_num_threads()}, "
        f"threading layer {numba.threading_layer()}"
    )
    scene = jellysim.load_scene(SCENE, {**changes, "duration": args.duration})
    frames = scene.frame_count - 1
    substeps = ", ".join(
        f"{g.name} {g.scene.tentacles.count}x{g.scene.tentacles.particles} {g.plan.substeps}/frame"
        for g in warm.groups  # type: ignore[attr-defined]
    )
    work = particle_steps_per_frame(warm) * frames
    print(
        f"{SCENE}, {args.duration:g} s simulated, {frames} frames; {substeps}; "
        f"output {'off' if args.no_output else 'on'}" + "".join(f"; {item}" for item in args.set)
    )
    print(
        f"{'repeat':>6} {'wall [s]':>9} {'CPU [s]':>8} {'particle-steps/s':>17} "
        f"{'load average':>13}"
    )
    for repeat in range(args.repeats):
        wall, cpu = timed_run(args.duration, not args.no_output, changes)
        load = os.getloadavg()[0]
        print(f"{repeat:>6d} {wall:>9.2f} {cpu:>8.2f} {work / wall:>17.3g} {load:>13.2f}")
    if args.parts:
        parts(args.duration, changes)


if __name__ == "__main__":
    run_main(main)
