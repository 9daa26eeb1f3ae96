"""Numba's threading layer is jellysim's choice unless the user makes it (issue 24): OpenMP, then
the workqueue, TBB last. With TBB installed (Debian's libtbb12, which Blender and OpenCV bring),
Numba would take TBB first, and a run on a shared 2-core machine crawled and hung at exit in TBB's
finalization (Numba issue #10556). CI installs libtbb12 (``make test``), so there these tests
also show that TBB was there to be avoided."""

from __future__ import annotations

import ctypes
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

PROBE = """
import sys
if sys.argv[1] == "numba-first":
    import numba  # a script that imports Numba before jellysim
import jellysim  # noqa: F401
import numba
import numpy as np

@numba.njit(parallel=True)
def add_one(a):
    for i in numba.prange(a.size):
        a[i] += 1.0

add_one(np.zeros(64))
print(numba.threading_layer(), " ".join(numba.config.THREADING_LAYER_PRIORITY))
"""


def _tbb_installed() -> bool:
    try:
        ctypes.CDLL("libtbb.so.12")  # what Numba's TBB layer loads
    except OSError:
        return False
    return True


def _probe(*, order: str = "jellysim-first", **variables: str) -> tuple[str, str]:
    layer, priority, _ = _probe_with_stderr(order=order, **variables)
    return layer, priority


def _probe_with_stderr(*, order: str = "jellysim-first", **variables: str) -> tuple[str, str, str]:
    unset = ("NUMBA_THREADING_LAYER", "OMP_WAIT_POLICY", "GOMP_SPINCOUNT", "OMP_DISPLAY_ENV")
    env = {k: v for k, v in os.environ.items() if not k.startswith(unset)}
    env.update(variables)
    done = subprocess.run(
        [sys.executable, "-c", PROBE, order],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    layer, priority = done.stdout.split(maxsplit=1)
    return layer, priority.strip(), done.stderr


def _spin_count(order: str = "jellysim-first", **variables: str) -> int:
    """How long GNU OpenMP's idle threads spin before they sleep, as libgomp took it when Numba's
    OpenMP layer loaded it (OMP_DISPLAY_ENV=verbose): 0 under the passive policy, 300,000 by
    default."""
    layer, _, stderr = _probe_with_stderr(order=order, OMP_DISPLAY_ENV="verbose", **variables)
    if layer != "omp":
        if os.environ.get("CI"):
            pytest.fail(f"Numba took {layer}, not OpenMP: make test installs libgomp1 as root")
        pytest.skip(f"Numba took {layer}: GNU OpenMP (libgomp1) is not installed")
    match = re.search(r"GOMP_SPINCOUNT = '(\d+)'", stderr)
    assert match, stderr
    return int(match.group(1))


@pytest.mark.parametrize("order", ["jellysim-first", "numba-first"])
def test_jellysim_puts_openmp_and_the_workqueue_before_tbb(order: str) -> None:
    layer, priority = _probe(order=order)
    assert priority == "omp workqueue tbb"
    assert layer in ("omp", "workqueue")


def test_the_users_choice_stands() -> None:
    assert _probe(NUMBA_THREADING_LAYER="workqueue")[0] == "workqueue"
    layer, priority = _probe(NUMBA_THREADING_LAYER_PRIORITY="workqueue omp tbb")
    assert (layer, priority) == ("workqueue", "workqueue omp tbb")


@pytest.mark.parametrize("order", ["jellysim-first", "numba-first"])
def test_openmp_threads_sleep_between_kernels(order: str) -> None:
    """Spinning threads starve on shared cores: on 16 cores with 16 busy processes the 3-D tank
    ran 1.07 steps/s spinning and 3.00 passive (docs/decisions.md, "Threading layer")."""
    assert _spin_count(order) == 0


def test_the_users_wait_policy_stands() -> None:
    assert _spin_count(OMP_WAIT_POLICY="active") > 300_000
    assert _spin_count(GOMP_SPINCOUNT="300000") == 300_000


def test_tbb_is_there_to_avoid_in_ci() -> None:
    if not _tbb_installed():
        if os.environ.get("CI"):
            pytest.fail("libtbb12 is not installed: make test installs it as root")
        pytest.skip("libtbb12 is not installed (make test installs it as root)")
    assert _probe(NUMBA_THREADING_LAYER="tbb")[0] == "tbb"  # Numba could have taken it
    assert _probe()[0] != "tbb"


def test_a_run_exits_within_seconds_of_writing_its_result(tmp_path: Path) -> None:
    """A fluid run (parallel kernels on every step) ends promptly after its last line."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_THREADING_LAYER")}
    command = [
        sys.executable, "-m", "jellysim", "run", "dam-break-2d", "--out", str(tmp_path),
        "--set", "fluid.spacing=0.01", "--set", "duration=0.02",
    ]  # fmt: skip
    process = subprocess.Popen(
        command, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    assert process.stdout is not None
    written = None
    for line in process.stdout:
        if "wrote" in line:
            written = time.monotonic()
    assert process.wait(timeout=60) == 0
    assert written is not None
    assert time.monotonic() - written < 5.0
