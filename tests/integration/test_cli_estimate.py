"""``jellysim run`` refuses, within seconds and before writing anything, a run the machine cannot
hold (issue 24): exit 2 with one line giving the estimate and the limit; a very long run says its
estimate first and goes on; ``--no-estimate-check`` overrides a refusal."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from jellysim.cli.main import main
from jellysim.config import load_scene
from jellysim.simulation import estimate as estimate_module
from jellysim.simulation.estimate import available_memory, estimate

SRC = Path(__file__).resolve().parents[2] / "src"
# within this many seconds of starting, imports included (about 1 s here)
REFUSED_WITHIN = 20.0


def jellysim_run(*args: str, cwd: Path) -> tuple[subprocess.CompletedProcess[str], float]:
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    start = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "jellysim", "run", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=120,
    )
    return done, time.monotonic() - start


def assert_refused(done: subprocess.CompletedProcess[str], seconds: float, out: Path) -> str:
    assert done.returncode == 2, done.stderr
    assert seconds < REFUSED_WITHIN
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert "Traceback" not in done.stderr
    assert not out.exists()  # nothing written
    return lines[0]


def test_ten_billion_frames_are_refused_for_the_disk(tmp_path: Path) -> None:
    out = tmp_path / "huge"
    done, seconds = jellysim_run(
        "brown-jelly", "--set", "fps=10000", "--set", "duration=1e6", "--out", str(out),
        cwd=tmp_path,
    )  # fmt: skip
    line = assert_refused(done, seconds, out)
    assert "would write about" in line and "TiB (10,000,000,001 frames)" in line
    assert "free for" in line and "--no-estimate-check" in line


def test_a_courant_number_of_1e_9_is_refused_naming_the_key(tmp_path: Path) -> None:
    out = tmp_path / "slow"
    done, seconds = jellysim_run(
        "dam-break-2d", "--set", "fluid.courant=1e-9", "--out", str(out), cwd=tmp_path
    )
    line = assert_refused(done, seconds, out)
    assert "fluid.courant = 1e-09" in line
    assert "MPS steps a frame" in line and "at most 10,000" in line


# 500 x 125 x 300 = 18.75 million water particles in tank-3d's tank (19.5 million lattice cells,
# under the scene's cap of 20 million): about 100 GiB at the peak.
HUGE_TANK = {
    "fluid.geometry": "hydrostatic",
    "fluid.spacing": 0.0008,
    "fluid.tank_height": 0.24,
    "fluid.water_height": 0.24,
}


def test_a_tank_beyond_the_memory_is_refused_without_allocating(tmp_path: Path) -> None:
    needed = estimate(load_scene("tank-3d", HUGE_TANK)).memory_bytes
    if needed <= available_memory():
        pytest.skip(f"this machine has the {needed / 2**30:.0f} GiB the scene needs")
    out = tmp_path / "tank"
    sets = [arg for key, value in HUGE_TANK.items() for arg in ("--set", f"{key}={value}")]
    done, seconds = jellysim_run("tank-3d", *sets, "--out", str(out), cwd=tmp_path)
    line = assert_refused(done, seconds, out)
    assert "of memory (neighbour lists" in line and "available" in line


def test_no_estimate_check_overrides_a_refusal(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(estimate_module, "available_memory", lambda: 1024)
    run = ["run", "forced-tentacles", "--set", "duration=0.1", "--quiet"]
    assert main([*run, "--out", str(tmp_path / "a")]) == 2
    assert "more than the 1 KiB available" in capsys.readouterr().err
    assert main([*run, "--out", str(tmp_path / "b"), "--no-estimate-check"]) == 0
    assert (tmp_path / "b" / "result.h5").is_file()


def test_a_long_run_says_its_estimate_first_and_goes_on(tmp_path: Path) -> None:
    """About an hour by the estimate: the first line on stderr says so, then the run starts
    (stopped here once it has)."""
    sets = ["fps=1", "duration=100", "tentacles.count=100", "tentacles.particles=1000"]
    assert estimate(load_scene("forced-tentacles", sets)).seconds > 600
    args = [arg for item in sets for arg in ("--set", item)]
    command = [sys.executable, "-m", "jellysim", "run", "forced-tentacles", *args]
    process = subprocess.Popen(
        [*command, "--out", str(tmp_path / "long")],
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(SRC)},
    )
    try:
        assert process.stderr is not None
        first = process.stderr.readline()
        second = process.stderr.readline()  # the run started: the loop describes itself
    finally:
        process.kill()
        process.wait()
    assert first.startswith("estimated cost: ") and " min (101 frames, " in first
    assert "100 tentacles x 1000 particles" in second
