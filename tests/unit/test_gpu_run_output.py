"""What `jellysim run --device cuda` prints: the run's own progress and notices, not
numba-cuda's INFO log of every allocation on the GPU ("dealloc: cuMemFree 24 bytes", some
hundreds of lines a frame, seen on an H200 with `jellysim run moon-jelly-fine --device cuda`,
2026-11-27) nor its warning at each launch of a deliberately small grid."""

from __future__ import annotations

import logging
import warnings

import pytest

from jellysim.cli.main import log_to_stderr

# numba-cuda's driver module, whose logger is made without a level of its own when the root
# logger already has a handler (numba_cuda/numba/cuda/cudadrv/driver.py, make_logger)
DRIVER = "numba_cuda.numba.cuda.cudadrv.driver"


def test_the_run_log_leaves_the_gpu_drivers_allocations_out(monkeypatch, capsys) -> None:
    root = logging.getLogger()
    monkeypatch.setattr(root, "handlers", [])  # a fresh `jellysim run`: nothing configured
    monkeypatch.setattr(root, "level", root.level)
    for name in ("numba", "numba_cuda"):
        monkeypatch.setattr(logging.getLogger(name), "level", logging.getLogger(name).level)
    log_to_stderr()
    logging.getLogger(DRIVER).info("dealloc: cuMemFree 24 bytes")
    logging.getLogger("jellysim.simulation.run").info("simulating: 1/2 frames (50 %)")
    logging.getLogger(DRIVER).warning("the driver's own warning")
    for handler in root.handlers:
        handler.flush()
    err = capsys.readouterr().err
    assert err.splitlines() == ["simulating: 1/2 frames (50 %)", "the driver's own warning"]


def test_small_launch_grids_do_not_warn() -> None:
    numba_errors = pytest.importorskip("numba.core.errors")
    import jellysim.fluid.gpu  # noqa: F401 - its import installs the filter

    with warnings.catch_warnings(record=True) as caught:
        for grid in (1, 37):
            warnings.warn(
                f"Grid size {grid} will likely result in GPU under-utilization due to low "
                "occupancy.",
                numba_errors.NumbaPerformanceWarning,
                stacklevel=1,
            )
        warnings.warn("another warning", numba_errors.NumbaPerformanceWarning, stacklevel=1)
    assert [str(w.message) for w in caught] == ["another warning"]
