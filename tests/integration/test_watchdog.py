"""The watchdog: a diverging run stops with SimulationUnstable / exit status 3, names the time and
the tentacle, and every frame written before stays readable (DESIGN §3)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

import jellysim
from jellysim import fields

OVERRIDES = {"duration": 1.0, "fps": 30.0, "tentacles.count": 3, "tentacles.particles": 20}
BROKEN = 1  # the tentacle whose state is corrupted
CLEAN = 5  # frames 0..CLEAN are computed before the corruption


def _scene() -> jellysim.Scene:
    # brown-jelly's marginal tentacles alone, one group: the hooks below count the calls of the
    # compiled step, which a grouped scene makes once a group a frame (its oral arms' too)
    return jellysim.load_scene("brown-jelly", OVERRIDES).group_scene(0)


def _assert_clean_frames(folder: Path, clean: int) -> int:
    """Frames 0..clean are stored, readable and finite; returns the frame count."""
    with jellysim.open_result(folder) as r:
        frames = r.frames
        assert clean + 1 <= frames < r.expected_frames
        np.testing.assert_allclose(r.time, np.arange(frames) / OVERRIDES["fps"], rtol=1e-12)
        for name in (
            fields.TENTACLE_POSITION.path,
            fields.TENTACLE_VELOCITY.path,
            fields.BELL_RIM.path,
            fields.BELL_MARGIN.path,
        ):
            data = r.file[name][: clean + 1]
            assert np.all(np.isfinite(data)), f"{name} is not finite in frames 0..{clean}"
        positions = r.tentacle_positions[: clean + 1]
    lengths = np.linalg.norm(np.diff(positions, axis=2), axis=3)
    assert np.abs(lengths / _scene().tentacles.spacing - 1.0).max() <= 1e-6
    return frames


Corruption = Callable[[jellysim.Simulation], None]


def _corrupt_after(frame: int, corrupt: Corruption) -> Corruption:
    """An observer that corrupts the state once frame ``frame`` has been computed and stored."""

    def observer(simulation: jellysim.Simulation) -> None:
        if simulation.frame == frame + 1:
            corrupt(simulation)

    return observer


def _nan_velocity(simulation: jellysim.Simulation) -> None:
    simulation.velocities[BROKEN, 7] = np.nan


def _nan_position(simulation: jellysim.Simulation) -> None:
    simulation.positions[BROKEN, 4:, 2] = np.nan


@pytest.mark.parametrize("corrupt", [_nan_velocity, _nan_position])
def test_api_raises_simulation_unstable(tmp_path: Path, corrupt: Corruption) -> None:
    scene = _scene()
    with pytest.raises(jellysim.SimulationUnstable) as caught:
        jellysim.run(scene, tmp_path, observers=[_corrupt_after(CLEAN, corrupt)])
    err = caught.value
    assert err.exit_status == 3
    assert err.tentacle == BROKEN
    # The corruption happened at the end of frame CLEAN + 1; the watchdog stops within a frame.
    frame_dt = 1.0 / scene.fps
    assert (CLEAN + 1) * frame_dt <= err.time <= (CLEAN + 2) * frame_dt + 1e-12
    assert f"{err.time:.6g}" in str(err)
    assert f"tentacle {BROKEN}" in str(err)
    _assert_clean_frames(tmp_path, CLEAN)


@pytest.mark.parametrize("velocity", [1.0e3, np.nan])
def test_api_watchdog_catches_a_bad_kernel_step(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, velocity: float
) -> None:
    """A step whose velocities run away (huge or NaN) stops at that frame, before it is written.

    (A huge velocity set by an observer does not do: the implicit drag of the next step damps it
    physically, so the state is wrapped right after the compiled step instead.)
    """
    real_advance_frame = jellysim.simulation.tentacles.advance_frame
    calls = 0

    def advance_frame(positions: np.ndarray, velocities: np.ndarray, *args: object) -> None:
        nonlocal calls
        real_advance_frame(positions, velocities, *args)
        calls += 1
        if calls == CLEAN + 1:
            velocities[BROKEN, 1:] = velocity

    monkeypatch.setattr(jellysim.simulation.tentacles, "advance_frame", advance_frame)
    scene = _scene()
    with pytest.raises(jellysim.SimulationUnstable) as caught:
        jellysim.run(scene, tmp_path)
    err = caught.value
    assert err.tentacle == BROKEN
    assert err.time == pytest.approx((CLEAN + 1) / scene.fps, rel=1e-12)
    assert f"{err.time:.6g}" in str(err) and f"tentacle {BROKEN}" in str(err)
    assert _assert_clean_frames(tmp_path, CLEAN) == CLEAN + 1


def test_api_observers_attribute() -> None:
    """Observers added to Simulation.observers see every frame in order; the state steps on."""
    simulation = jellysim.Simulation(_scene())
    seen: list[int] = []
    simulation.observers.append(lambda s: seen.append(s.frame))
    simulation.observers.append(_corrupt_after(CLEAN, _nan_velocity))
    with pytest.raises(jellysim.SimulationUnstable) as caught:
        for _ in range(simulation.scene.frame_count - 1):
            simulation.step_frame()
    assert seen == list(range(1, CLEAN + 2))
    assert caught.value.tentacle == BROKEN
    # The watchdog runs after the observers: the corrupted frame itself is caught.
    assert caught.value.time == pytest.approx((CLEAN + 1) / simulation.scene.fps, rel=1e-9)


SCRIPT = textwrap.dedent(
    """
    import sys

    import numpy as np

    import jellysim.simulation.tentacles
    from jellysim.cli.main import main

    real_advance_frame = jellysim.simulation.tentacles.advance_frame
    calls = 0


    def advance_frame(positions, *args):
        global calls
        real_advance_frame(positions, *args)
        calls += 1
        if calls == {calls}:
            positions[{tentacle}, 3:] = np.nan


    jellysim.simulation.tentacles.advance_frame = advance_frame
    sys.exit(main(sys.argv[1:]))
    """
)


def _run_broken_cli(out: Path) -> subprocess.CompletedProcess[str]:
    script = SCRIPT.format(calls=CLEAN, tentacle=BROKEN)
    scene_file = out.parent / f"{out.name}-scene.toml"  # _scene() as a user's scene file
    scene_file.write_text(jellysim.scene_to_toml(_scene()), encoding="utf-8")
    return subprocess.run(
        [sys.executable, "-c", script, "run", str(scene_file), "--out", str(out), "--quiet"],
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.fixture(scope="module")
def broken_cli(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Path, subprocess.CompletedProcess[str]]:
    out = tmp_path_factory.mktemp("unstable")
    return out, _run_broken_cli(out)


def test_cli_exit_status_3(broken_cli: tuple[Path, subprocess.CompletedProcess[str]]) -> None:
    out, done = broken_cli
    assert done.returncode == 3, done.stderr
    assert "Traceback" not in done.stderr
    assert done.stdout == ""
    message = done.stderr
    # NaN appears in the state of frame CLEAN: the failure is at t in [CLEAN, CLEAN + 1] / fps.
    fps = OVERRIDES["fps"]
    times = [float(word) for word in message.replace("=", " ").split() if _is_number(word)]
    assert any(CLEAN / fps <= t <= (CLEAN + 1) / fps for t in times), message
    assert f"tentacle {BROKEN}" in message
    assert "dt_safety" in message  # what to change
    assert len(message.strip().splitlines()) <= 3
    _assert_clean_frames(out, CLEAN - 1)


def test_cli_no_non_finite_frame_is_written(
    broken_cli: tuple[Path, subprocess.CompletedProcess[str]],
) -> None:
    out, done = broken_cli
    assert done.returncode == 3
    with jellysim.open_result(out) as r:
        assert r.frames == CLEAN
        assert np.all(np.isfinite(r.tentacle_positions))


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return "." in word
