"""Shared pytest set-up: one floating-point path on every x86-64 host (``pinning``, imported
before anything loads NumPy), and tests marked ``slow`` run only with ``--runslow``."""

from __future__ import annotations

import os

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
