"""Shared pytest set-up: one floating-point path on every x86-64 host (``pinning``, imported
before anything loads NumPy), and tests marked ``slow`` run only with ``--runslow``."""

from __future__ import annotations

import os
import sys
import threading
import traceback
from collections.abc import Iterator
from typing import Any

import pinning  # noqa: F401  (first: it sets the environment NumPy and Numba read on import)
import pytest

# The GPU path's kernels run in Numba's CUDA simulator (read when Numba loads), unless the suite
# runs on a GPU for them (make test-gpu sets JELLYSIM_TEST_GPU=1).
if os.environ.get("JELLYSIM_TEST_GPU") != "1":
    os.environ.setdefault("NUMBA_ENABLE_CUDASIM", "1")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--runslow", action="store_true", default=False, help="also run tests marked slow"
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow: run with --runslow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


# Numba's CUDA simulator runs each GPU thread of a block in a Python thread, and a kernel's
# barriers wait for every one of them: at Python's default switch interval (5 ms) the thread
# holding the GIL keeps the rest waiting that long at each turn. At 0.1 ms the simulated GPU
# tests run about 4x faster (test_a_two_level_run_resumes_to_the_bit: 198 s at 5 ms, 47 s at
# 0.1 ms, on the 2-core CI host), with the same results (the kernels' sums are in a fixed order).
SIMULATOR_SWITCH_INTERVAL = 1e-4
_SHARED_LOCK = threading.Lock()


def _shared_array(self: Any, shape: Any, dtype: Any) -> Any:
    """numba.cuda.simulator's FakeCUDAShared.array with its look-up and allocation under a lock.
    The simulator's own is not thread-safe: two threads of a block that reach a
    ``cuda.shared.array`` line together can each allocate one, and then share nothing (seen at
    0.1 ms switches as a scan of garbage; at 5 ms the first thread always allocated first). One
    array a call site (file, line) and launch, as there."""
    import numpy as np
    from numba.core import types
    from numba.np import numpy_support

    if isinstance(dtype, types.Type):
        dtype = numpy_support.as_dtype(dtype)
    if shape == 0:  # dynamic shared memory: the simulator's own (no allocation)
        return _SIMULATOR_SHARED_ARRAY(self, shape, dtype)
    caller = tuple(traceback.extract_stack(sys._getframe())[-2][0:2])
    with _SHARED_LOCK:
        found = self._allocations.get(caller)
        if found is None:
            found = np.empty(shape, dtype)
            self._allocations[caller] = found
    return found


_SIMULATOR_SHARED_ARRAY: Any = None


@pytest.fixture(autouse=True)
def _quick_thread_switches_in_the_cuda_simulator(
    request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch
) -> Iterator[None]:
    global _SIMULATOR_SHARED_ARRAY
    simulated = os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0")
    if not (simulated and request.node.path.name.endswith("_gpu.py")):
        yield
        return
    from numba.cuda.simulator import kernelapi

    if _SIMULATOR_SHARED_ARRAY is None:
        _SIMULATOR_SHARED_ARRAY = kernelapi.FakeCUDAShared.array
    monkeypatch.setattr(kernelapi.FakeCUDAShared, "array", _shared_array)
    previous = sys.getswitchinterval()
    sys.setswitchinterval(SIMULATOR_SWITCH_INTERVAL)
    try:
        yield
    finally:
        sys.setswitchinterval(previous)
