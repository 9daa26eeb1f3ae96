"""Numba's threading layers side by side: ``jellysim run`` of a scene under each layer, with and
without other work on the cores.

    .venv/bin/python benchmarks/bench_threads.py [--scene dam-break-2d] [--set KEY=VALUE ...]
        [--layer omp --layer workqueue --layer tbb] [--load 0 --load 2] [--timeout 300]

Each run is a fresh process (``python -m jellysim run SCENE``) with
``NUMBA_THREADING_LAYER`` set to the layer; ``--load N`` starts N busy processes (pure Python
loops) for the run's duration, as other work sharing the machine. Reported per run: the wall time
to the "wrote" line, the time from it to the process's exit (TBB's finalization hang shows here),
or that the run did not end within ``--timeout`` seconds (it is then killed). Kernels are compiled
once first (not timed).
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import platform
import subprocess
import sys
import tempfile
import threading
import time


def busy(stop: float) -> None:
    """Spin until the monotonic time ``stop``."""
    total = 0
    while time.monotonic() < stop:
        total += 1


def run(scene: str, sets: list[str], layer: str, load: int, timeout: float) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_THREADING_LAYER")}
    env["NUMBA_THREADING_LAYER"] = layer
    workers = [
        multiprocessing.Process(target=busy, args=(time.monotonic() + timeout,), daemon=True)
        for _ in range(load)
    ]
    for worker in workers:
        worker.start()
    with tempfile.TemporaryDirectory() as out:
        command = [sys.executable, "-m", "jellysim", "run", scene, "--out", out]
        for item in sets:
            command += ["--set", item]
        start = time.monotonic()
        process = subprocess.Popen(
            command, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        lines: list[tuple[float, str]] = []  # read aside: a hung process writes no more

        def read() -> None:
            assert process.stdout is not None
            for line in process.stdout:
                lines.append((time.monotonic(), line))

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        try:
            process.wait(timeout=timeout)
            ended = time.monotonic()
            reader.join(timeout=5.0)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
            ended = None
        written = next((when for when, line in lines if "wrote" in line), None)
        if written is None:
            answer = (
                f"no result within {timeout:g} s"
                if ended is None
                else f"failed (exit status {process.returncode})"
            )
        elif ended is None:
            answer = f"{written - start:.1f} s to the result, then no exit within {timeout:g} s"
        else:
            answer = f"{written - start:.1f} s to the result, exit {ended - written:.1f} s later"
    for worker in workers:
        worker.terminate()
    return answer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scene", default="dam-break-2d")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--layer", action="append", choices=("omp", "workqueue", "tbb"))
    parser.add_argument("--load", action="append", type=int)
    parser.add_argument("--timeout", type=float, default=300.0)
    args = parser.parse_args()
    layers = args.layer or ["omp", "workqueue", "tbb"]
    loads = args.load or [0, os.cpu_count() or 1]
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores; {args.scene} {args.set}")
    run(args.scene, args.set, "workqueue", 0, args.timeout)  # compile (cached for all layers)
    for load in loads:
        for layer in layers:
            print(f"{layer:>9}, {load} busy processes: ", end="", flush=True)
            print(run(args.scene, args.set, layer, load, args.timeout), flush=True)


if __name__ == "__main__":
    main()
