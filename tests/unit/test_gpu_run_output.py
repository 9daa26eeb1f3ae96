"""What `jellysim run --device cuda` prints: the run's own progress and notices, not
numba-cuda's INFO log of every allocation on the GPU ("dealloc: cuMemFree 24 bytes", some
hundreds of lines a frame, seen on an H200 with `jellysim run moon-jelly-fine --device cuda`,
2026-11-27) nor its warning at each launch of a deliberately small grid."""

from __future__ import annotations

import logging
import warnings

import pytest

from jellysim.cli.main import QUIET_LOGGERS, log_to_stderr

# numba-cuda's driver module, whose logger is made without a level of its own when the root
# logger already has a handler (numba_cuda/numba/cuda/cudadrv/driver.py, make_logger)
DRIVER = "numba_cuda.numba.cuda.cudadrv.driver"


def test_the_run_log_leaves_the_gpu_drivers_allocations_out(monkeypatch, capsys) -> None:
    root = logging.getLogger()
    monkeypatch.delenv("NUMBA_CUDA_LOG_LEVEL", raising=False)
    monkeypatch.setattr(root, "handlers", [])  # a fresh `jellysim run`: nothing configured
    names = ("", *QUIET_LOGGERS)
    levels = {name: logging.getLogger(name).level for name in names}
    try:
        log_to_stderr()
        logging.getLogger(DRIVER).info("dealloc: cuMemFree 24 bytes")
        logging.getLogger("jellysim.simulation.run").info("simulating: 1/2 frames (50 %)")
        logging.getLogger(DRIVER).warning("the driver's own warning")
        for handler in root.handlers:
            handler.flush()
    finally:  # setLevel, which also clears the loggers' cached levels
        for name, level in levels.items():
            logging.getLogger(name).setLevel(level)
    err = capsys.readouterr().err
    assert err.splitlines() == ["simulating: 1/2 frames (50 %)", "the driver's own warning"]


def test_small_launch_grids_do_not_warn() -> None:
    """The filter a GPU solver installs; numba-cuda's message as it reads with and without
    colorama's colour code (seen on the H200 machine's output)."""
    numba_errors = pytest.importorskip("numba.core.errors")
    from jellysim.fluid.gpu import quiet_small_grid_warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        quiet_small_grid_warnings()
        for prefix, grid in (("", 1), ("\x1b[1m", 37)):
            warnings.warn(
                f"{prefix}Grid size {grid} will likely result in GPU under-utilization due to "
                "low occupancy.",
                numba_errors.NumbaPerformanceWarning,
                stacklevel=1,
            )
        warnings.warn("another warning", numba_errors.NumbaPerformanceWarning, stacklevel=1)
    assert [str(w.message) for w in caught] == ["another warning"]


@pytest.mark.parametrize("quiet", [None, False, True])
def test_asking_a_scene_without_water_for_the_gpu_says_it_runs_on_the_cpu(
    quiet, caplog: pytest.LogCaptureFixture, tmp_path
) -> None:
    """`jellysim run brown-jelly --device cuda`: brown-jelly has no MPS water, so nothing goes
    to the GPU; the run goes on on the CPU (no GPU needed) and says so in one line, unless
    quiet."""
    import jellysim
    from jellysim.simulation.run import device_notice

    scene = jellysim.load_scene("brown-jelly", {"duration": 0.05, "fluid.device": "cuda"})
    expected = device_notice(scene)
    assert expected is not None and expected.startswith("brown-jelly: fluid.device = 'cuda'")
    assert "fluid.model = 'none'" in expected
    assert device_notice(jellysim.load_scene("brown-jelly")) is None  # the CPU, as asked
    with caplog.at_level(logging.INFO, logger="jellysim"):
        with jellysim.run(scene, tmp_path / "out", quiet=quiet) as result:
            assert result.frames == scene.frame_count
    said = [r for r in caplog.records if r.getMessage() == expected]
    assert [r.levelno for r in said] == ([] if quiet is True else [logging.WARNING])


@pytest.mark.parametrize("preset", ["dam-break-2d", "moon-jelly"])
def test_a_scene_with_water_on_the_gpu_gets_no_such_notice(preset) -> None:
    import jellysim
    from jellysim.simulation.run import device_notice

    assert device_notice(jellysim.load_scene(preset, {"fluid.device": "cuda"})) is None
