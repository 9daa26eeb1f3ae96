"""OpenMP parallel regions an MPS step starts, by kernel, and what one costs to start.

    .venv/bin/python benchmarks/parallel_regions.py [--case tank-3d] [--steps 10] [--threads N]
        [--set KEY=VALUE ...]

Each parallel loop of a Numba kernel is one OpenMP parallel region: the threads are woken at its
start and meet at its end. With jellysim's passive wait policy (docs/decisions.md, "Threading
layer") a sleeping thread is woken by the kernel, which costs tens of microseconds a region, so
the number of regions a step bounds how far the step scales with threads (issue 28).

The script builds a small library with the C compiler (``cc``, Debian's ``gcc``) that counts
libgomp's ``GOMP_parallel`` calls, runs itself again with it preloaded, steps the case of
``bench_fluid.py`` (tank-3d at 54,000 fluid particles by default) and prints the regions a step,
by kernel (each jellysim kernel called from Python, with the regions of the kernels it calls),
and the median time to start and end an empty region on these threads. ``--threads`` above the
cores is allowed for the count: ``NUMBA_NUM_THREADS`` is set to it, and the count does not
depend on the cores.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

COUNTER = r"""
#define _GNU_SOURCE
#include <dlfcn.h>
static unsigned long calls = 0;
typedef void (*parallel_t)(void (*)(void *), void *, unsigned, unsigned);
void GOMP_parallel(void (*fn)(void *), void *data, unsigned threads, unsigned flags) {
    static parallel_t real = 0;
    if (!real) {
        void *gomp = dlopen("libgomp.so.1", RTLD_NOW | RTLD_NOLOAD);
        if (!gomp) gomp = dlopen("libgomp.so.1", RTLD_NOW);
        real = (parallel_t)dlvsym(gomp, "GOMP_parallel", "GOMP_4.0");
    }
    calls++;
    real(fn, data, threads, flags);
}
unsigned long parallel_regions(void) { return calls; }
"""

LIBRARY = "JELLYSIM_REGION_COUNTER"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--case", default="tank-3d")
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    if args.steps < 1 or args.threads < 1:
        parser.error("--steps and --threads must be at least 1")
    from bench_fluid import CASES  # benchmarks/

    from jellysim.errors import InputError

    if args.case not in CASES:
        raise InputError(f"unknown case {args.case!r} (one of {', '.join(CASES)})")
    if LIBRARY not in os.environ:
        relaunch(args)
        return
    count_regions(args)


def relaunch(args: argparse.Namespace) -> None:
    """Build the counting library and run this script again with it preloaded."""
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        sys.exit("parallel_regions.py: error: no C compiler (apt-get install gcc)")
    with tempfile.TemporaryDirectory() as folder:
        source, library = Path(folder, "count.c"), Path(folder, "libcount.so")
        source.write_text(COUNTER)
        subprocess.run(
            [compiler, "-shared", "-fPIC", "-O2", "-o", library, source, "-ldl"], check=True
        )
        env = {
            **os.environ,
            LIBRARY: str(library),
            "LD_PRELOAD": str(library),
            "NUMBA_NUM_THREADS": str(args.threads),
        }
        done = subprocess.run([sys.executable, *sys.argv], env=env)
    sys.exit(done.returncode)


def count_regions(args: argparse.Namespace) -> None:
    import ctypes
    import importlib
    import pkgutil
    import time
    from collections import Counter

    import numba
    import numpy as np
    from bench_fluid import CASES
    from numba.core.registry import CPUDispatcher

    import jellysim  # first: jellysim's threading layer and wait policy
    import jellysim.fluid
    from jellysim.config.load import parse_override
    from jellysim.simulation.fluid import FluidSimulation

    counter = ctypes.CDLL(os.environ[LIBRARY])
    counter.parallel_regions.restype = ctypes.c_ulong
    numba.set_num_threads(args.threads)
    preset, overrides = CASES[args.case]
    overrides = {**overrides, **dict(parse_override(item) for item in args.set)}
    solver = FluidSimulation(jellysim.load_scene(preset, overrides)).solver
    solver.step(solver.stable_dt())  # compile, or load from the cache, before the counting

    regions: Counter[str] = Counter()
    modules = [
        importlib.import_module(f"jellysim.fluid.{module.name}")
        for module in pkgutil.iter_modules(jellysim.fluid.__path__)
    ]
    counted: dict[int, object] = {}

    def counting(name: str, kernel: CPUDispatcher) -> object:
        def call(*arguments: object) -> object:
            before = counter.parallel_regions()
            result = kernel(*arguments)
            regions[name] += counter.parallel_regions() - before
            return result

        return call

    # The kernels called from Python, each replaced in its module by a counting wrapper. A
    # compiled kernel that calls another keeps its own reference; one compiled for the first
    # time from here on would find a wrapper and fail to type, so the first step above, before
    # the wrapping, has compiled (or loaded) every kernel the steps use.
    for module in modules:
        for name, value in list(vars(module).items()):
            if isinstance(value, CPUDispatcher):
                label = f"{value.__module__.rsplit('.', 1)[-1]}.{name}"
                counted.setdefault(id(value), counting(label, value))
                setattr(module, name, counted[id(value)])
    before = counter.parallel_regions()
    for _ in range(args.steps):
        solver.step(solver.stable_dt())
    total = (counter.parallel_regions() - before) / args.steps
    print(
        f"{args.case}: {numba.get_num_threads()} threads ({os.cpu_count()} cores), "
        f"layer {numba.threading_layer()}, OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY')}: "
        f"{total:.1f} parallel regions a step ({args.steps} steps)"
    )
    for name, count in regions.most_common():
        if count:
            print(f"  {name:40s} {count / args.steps:7.1f}")

    @numba.njit(parallel=True)
    def empty(values: np.ndarray) -> None:
        for i in numba.prange(values.shape[0]):
            values[i] += 1.0

    values = np.zeros(4 * args.threads)
    empty(values)
    seconds = []
    for _ in range(1001):
        started = time.perf_counter()
        empty(values)
        seconds.append(time.perf_counter() - started)
    print(f"one empty region: {1e6 * float(np.median(seconds)):.1f} µs (median of 1,001)")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).parent))
    from _input import run_main  # benchmarks/: bad input in one line, exit 2

    run_main(main)
