"""``jellysim run --resume`` after a real SIGKILL continues bitwise identically (DESIGN §3)."""

from __future__ import annotations

import hashlib
import os
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import h5py
import numpy as np
import pytest
import scenes
import tomli_w
from faultkit import assert_invalid_input as _assert_invalid_input
from faultkit import assert_same_result as _assert_same_result
from faultkit import checkpoint_frame as _checkpoint_frame
from faultkit import datasets as _datasets
from faultkit import jellysim_run as _jellysim
from faultkit import run_command as _command
from faultkit import written_frames as _written_frames

import jellysim
from jellysim import fields

DURATION = 10.0
FPS = 30.0
# Checkpoints rarer than the result store's batches, so the file often holds frames past the
# last checkpoint (those a resume must recompute).
CHECKPOINT_EVERY = 50
# Small chains, many substeps: a few seconds of simulation, long enough to be killed mid-run.
SLOW = [
    f"duration={DURATION}",
    f"fps={FPS}",
    "tentacles.count=2",
    "tentacles.particles=20",
    f"solver.checkpoint_every={CHECKPOINT_EVERY}",
    "solver.dt_safety=0.01",
]
FRAMES = round(DURATION * FPS) + 1


def _digest(path: Path) -> tuple[str, int]:
    return hashlib.sha256(path.read_bytes()).hexdigest(), path.stat().st_mtime_ns


def _fingerprint(folder: Path) -> dict[str, tuple[str, int]]:
    return {p.name: _digest(p) for p in sorted(folder.iterdir()) if p.is_file()}


def _kill_mid_run(
    out: Path, overrides: list[str] = SLOW, preset: str = "brown-jelly"
) -> tuple[int, int]:
    """Start the slow run and SIGKILL it once result.h5 holds frames past a checkpoint.

    Returns the frame count and the checkpoint frame read just before the kill.
    """
    process = subprocess.Popen(
        _command(out, overrides, preset=preset),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 300.0
    try:
        while True:
            if process.poll() is not None:
                _, err = process.communicate()
                pytest.fail(f"the run ended (status {process.returncode}) before the kill: {err}")
            if time.monotonic() > deadline:
                pytest.fail("result.h5 held no frames past a checkpoint within 300 s")
            checkpoint = _checkpoint_frame(out)
            if checkpoint is not None:
                frames = _written_frames(out)
                if frames > checkpoint + 1:
                    break
            time.sleep(0.01)
        os.kill(process.pid, signal.SIGKILL)
    finally:
        if process.poll() is None:
            process.kill()  # a failure above; after os.kill a second SIGKILL is harmless
        process.communicate()
    assert process.returncode == -signal.SIGKILL
    return frames, checkpoint


def test_resume_after_sigkill_is_bitwise_identical(tmp_path: Path) -> None:
    killed = tmp_path / "killed"
    polled, polled_checkpoint = _kill_mid_run(killed)

    # The killed file opens (its SWMR writer never closed it) and holds every reported frame.
    with jellysim.open_result(killed) as r:
        frames = r.frames
        assert polled <= frames < FRAMES
        assert r.expected_frames == FRAMES
        assert not r.complete
        np.testing.assert_allclose(r.time, np.arange(frames) / FPS, rtol=1e-12)
        for name in (
            fields.TENTACLE_POSITION.path,
            fields.TENTACLE_VELOCITY.path,
            fields.BELL_RIM.path,
            fields.BELL_MARGIN.path,
        ):
            # ``time`` is extended last in each batch: the other datasets are at least as long.
            assert r.file[name].shape[0] >= frames
            data = r.file[name][:frames]
            assert np.all(np.isfinite(data)), f"{name} holds non-finite values"
    checkpoint_frame = _checkpoint_frame(killed)
    assert checkpoint_frame is not None
    assert checkpoint_frame % CHECKPOINT_EVERY == 0
    assert polled_checkpoint <= checkpoint_frame <= frames - 1

    # Resuming with another scene is invalid input and touches nothing.
    before = _fingerprint(killed)
    _assert_invalid_input(_jellysim(killed, [*SLOW, "tentacles.youngs_modulus=200"], "--resume"))
    assert _fingerprint(killed) == before

    resumed = _jellysim(killed, SLOW, "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert resumed.stdout == resumed.stderr == ""
    assert not (killed / "checkpoint.npz").exists()
    with jellysim.open_result(killed) as r:
        assert r.frames == FRAMES and r.complete

    reference = tmp_path / "reference"
    done = _jellysim(reference, SLOW)
    assert done.returncode == 0, done.stderr
    _assert_same_result(killed, reference)
    assert (killed / "scene.toml").read_text() == (reference / "scene.toml").read_text()


# The soft bell in its fluid (issue 6): a small tank, two tentacles, checkpoints every 4 frames.
# The preset under gravity (mixed source, corrected gradient, 9 MPS steps a 1/20 s frame here): a
# simulated second takes about 14 s, so 2.5 s of simulation leaves the poller many flushed
# batches to catch (in weightless water, 4 s a second, 1.0 s once finished before the kill in CI).
SOFT_FPS = 20.0
SOFT_DURATION = 2.5
SOFT = [
    f"duration={SOFT_DURATION}",
    f"fps={SOFT_FPS}",
    "tentacles.count=2",
    "solver.checkpoint_every=4",
    *(f"{key}={value}" for key, value in scenes.SMALL_MOON.items()),
]


def test_soft_bell_resume_after_sigkill_is_bitwise_identical(tmp_path: Path) -> None:
    """Particles, springs' state, muscle phase, tentacles and the pressure warm start all come
    back from the checkpoint: the resumed run equals an uninterrupted one bit for bit."""
    killed = tmp_path / "killed"
    frames, _ = _kill_mid_run(killed, SOFT, preset="moon-jelly")
    assert frames < round(SOFT_DURATION * SOFT_FPS) + 1
    resumed = _jellysim(killed, SOFT, "--resume", preset="moon-jelly")
    assert resumed.returncode == 0, resumed.stderr
    reference = tmp_path / "reference"
    done = _jellysim(reference, SOFT, preset="moon-jelly")
    assert done.returncode == 0, done.stderr
    _assert_same_result(killed, reference)
    found = _datasets(reference)
    assert {
        fields.BELL_POSITION.path,
        fields.BELL_SURFACE_VERTICES.path,
        fields.FLUID_POSITION.path,
        fields.TENTACLE_POSITION.path,
    } <= (found.keys())


def test_resume_of_a_finished_run_changes_nothing(tmp_path: Path) -> None:
    quick = ["duration=0.5", "tentacles.count=2", "tentacles.particles=20"]
    assert _jellysim(tmp_path, quick).returncode == 0
    before = _fingerprint(tmp_path)
    assert set(before) == {"result.h5", "result.xdmf", "scene.toml"}

    done = _jellysim(tmp_path, quick, "--resume")
    assert done.returncode == 0, done.stderr
    assert _fingerprint(tmp_path) == before

    _assert_invalid_input(_jellysim(tmp_path, [*quick, "tentacles.youngs_modulus=200"], "--resume"))
    assert _fingerprint(tmp_path) == before


def test_resume_invalid_requests_exit_2(tmp_path: Path) -> None:
    quick = ["duration=0.2", "tentacles.count=2", "tentacles.particles=20"]
    _assert_invalid_input(_jellysim(tmp_path / "nothing", quick, "--resume"))
    assert not (tmp_path / "nothing" / "result.h5").exists()
    _assert_invalid_input(_jellysim(tmp_path / "both", quick, "--resume", "--force"))
    assert not (tmp_path / "both" / "result.h5").exists()


class _Interrupt(Exception):
    pass


def test_api_resume_after_an_aborted_run_is_bitwise_identical(tmp_path: Path) -> None:
    """In-process: a run aborted by an exception mid-run resumes from its last checkpoint."""
    overrides = {
        "duration": 1.0,
        "tentacles.count": 3,
        "tentacles.particles": 20,
        "solver.checkpoint_every": 4,
    }
    scene = jellysim.load_scene("brown-jelly", overrides)

    def abort(simulation: jellysim.Simulation) -> None:
        if simulation.frame == 14:
            raise _Interrupt

    with pytest.raises(_Interrupt):
        jellysim.run(scene, tmp_path / "aborted", observers=[abort])
    with jellysim.open_result(tmp_path / "aborted") as r:
        assert r.frames == 14  # frames 0..13; frame 14 was aborted before it was written
    with np.load(tmp_path / "aborted" / "checkpoint.npz") as checkpoint:
        assert int(checkpoint["frame"]) == 12

    with jellysim.run(scene, tmp_path / "aborted", resume=True) as r:
        assert r.frames == scene.frame_count
    jellysim.run(scene, tmp_path / "reference").close()
    _assert_same_result(tmp_path / "aborted", tmp_path / "reference")


def _without_keys(text: str, keys: dict[str, tuple[str, ...]]) -> str:
    """Scene TOML ``text`` without ``keys`` (table -> key names), written as TOML again."""
    tree = tomllib.loads(text)
    for table, names in keys.items():
        for name in names:
            del tree[table][name]
    return tomli_w.dumps(tree)


def test_a_checkpoint_from_before_new_keys_resumes_and_another_scene_is_refused(
    tmp_path: Path,
) -> None:
    """A checkpoint's scene text written before a key existed (issue 26's flow.model,
    flow.direction and the drag keys) describes the same scene: its run resumes bit for bit.
    A text that sets any key differently is another scene and is refused."""
    overrides = {"duration": 0.5, "tentacles.count": 2, "solver.checkpoint_every": 4}
    scene = jellysim.load_scene("forced-tentacles", overrides)

    def abort(simulation: jellysim.Simulation) -> None:
        if simulation.frame == 6:
            raise _Interrupt

    with pytest.raises(_Interrupt):
        jellysim.run(scene, tmp_path / "old", observers=[abort])
    path = tmp_path / "old" / "checkpoint.npz"
    with np.load(path) as checkpoint:
        state = {key: checkpoint[key] for key in checkpoint.files}
    new_keys = {
        "flow": ("model", "direction"),
        "tentacles": ("drag", "normal_drag", "tangential_drag"),
    }
    older = _without_keys(str(state["scene"]), new_keys)
    assert "flow" in older and "direction" not in tomllib.loads(older)["flow"]
    assert older != str(state["scene"])
    shutil.copytree(tmp_path / "old", tmp_path / "other")
    # As the older version wrote them: the checkpoint's scene text and the result's.
    np.savez(path, **{**state, "scene": np.array(older)})
    with h5py.File(tmp_path / "old" / "result.h5", "r+") as f:
        f.attrs["scene"] = older
    with jellysim.run(scene, tmp_path / "old", resume=True) as r:
        assert r.frames == scene.frame_count
    jellysim.run(scene, tmp_path / "reference").close()
    # Every frame bit for bit; the result keeps the text it was started with.
    resumed, reference = _datasets(tmp_path / "old"), _datasets(tmp_path / "reference")
    assert resumed.keys() == reference.keys()
    for name, values in resumed.items():
        assert values.tobytes() == reference[name].tobytes(), name

    other = str(state["scene"]).replace('model = "bell"', 'model = "current"')
    assert other != str(state["scene"])
    np.savez(tmp_path / "other" / "checkpoint.npz", **{**state, "scene": np.array(other)})
    with pytest.raises(jellysim.InputError, match="the scene differs"):
        jellysim.run(scene, tmp_path / "other", resume=True)


def test_one_writer_per_folder_and_a_killed_run_leaves_no_lock(tmp_path: Path) -> None:
    """Issue 24: while a run writes a folder, a second run, --resume or --force on it is refused
    (exit 2); once the writer is SIGKILLed, the folder is free again."""
    out = tmp_path / "run"
    long = [*SLOW, f"duration={20 * DURATION}"]  # outlasts the refused attempts
    process = subprocess.Popen(
        _command(out, long), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        deadline = time.monotonic() + 300.0
        while _checkpoint_frame(out) is None:
            assert process.poll() is None, "the run ended before the test could race it"
            assert time.monotonic() < deadline, "no checkpoint within 300 s"
            time.sleep(0.01)
        _assert_invalid_input(_jellysim(out, long))  # a plain run: the result exists
        for extra in ("--force", "--resume"):
            done = _jellysim(out, long, extra)
            assert process.poll() is None, "the first run ended while the others were refused"
            _assert_invalid_input(done)
            assert "being written by another jellysim run" in done.stderr
        os.kill(process.pid, signal.SIGKILL)
    finally:
        if process.poll() is None:
            process.kill()
        process.communicate()
    again = _jellysim(out, SLOW, "--force")
    assert again.returncode == 0, again.stderr
    with jellysim.open_result(out) as r:
        assert r.complete


def test_the_writer_lock_refuses_in_process_too(tmp_path: Path) -> None:
    from jellysim.io.folders import writing_lock

    scene = jellysim.load_scene("brown-jelly", {"duration": 0.1})
    tmp_path.mkdir(exist_ok=True)
    with writing_lock(tmp_path):
        with pytest.raises(jellysim.InputError, match="being written by another jellysim run"):
            jellysim.run(scene, tmp_path)
        assert not (tmp_path / "result.h5").exists()
    jellysim.run(scene, tmp_path).close()  # released


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_stop_signal_ends_the_run_at_a_frame_with_a_checkpoint(
    tmp_path: Path, stop: signal.Signals
) -> None:
    """Issue 24: Ctrl-C (SIGINT) or SIGTERM ends a run at the next frame boundary: every frame
    written, a checkpoint of the last, one line saying how to resume, exit status 128 + the
    signal; the command it gives continues the run bit for bit."""
    out = tmp_path / "stopped"
    process = subprocess.Popen(
        _command(out, SLOW), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    deadline = time.monotonic() + 300.0
    while _written_frames(out) < 2:
        assert process.poll() is None, "the run ended before the signal"
        assert time.monotonic() < deadline
        time.sleep(0.01)
    process.send_signal(stop)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == 128 + stop, stderr
    assert stdout == "" and len(stderr.strip().splitlines()) == 1 and "Traceback" not in stderr
    assert stderr.startswith(f"jellysim: stopped by {stop.name} at t = ")
    frames = _written_frames(out)
    assert 2 <= frames < FRAMES
    assert _checkpoint_frame(out) == frames - 1
    resume = stderr.split("'")[1]
    assert resume == f"jellysim run {out / 'scene.toml'} --out {out} --resume"
    done = subprocess.run(
        [sys.executable, "-m", *resume.split()], capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr
    reference = tmp_path / "reference"
    assert _jellysim(reference, SLOW).returncode == 0
    _assert_same_result(out, reference)


def test_probes_resume_bitwise_identical(tmp_path: Path) -> None:
    """A fluid scene with an obstacle and probes (spheric-test2 at the regression case's coarse
    spacing) aborted mid-run resumes from its checkpoint to the uninterrupted run's probes and
    fluid, bit for bit: the pressure probes' frame means hold no state across frames."""
    overrides = {
        "fluid.spacing": 0.161 / 2,
        "fluid.tank_height": 0.7,
        "duration": 0.6,
        "fps": 20.0,
        "solver.checkpoint_every": 4,
    }
    scene = jellysim.load_scene("spheric-test2", overrides)

    def abort(simulation: jellysim.Simulation) -> None:
        if simulation.frame == 11:
            raise _Interrupt

    with pytest.raises(_Interrupt):
        jellysim.run(scene, tmp_path / "aborted", observers=[abort])
    with jellysim.run(scene, tmp_path / "aborted", resume=True) as r:
        assert r.frames == scene.frame_count
        assert r.probes()["P1"][0][8:].max() > 1000.0  # the impact falls in the resumed frames
    jellysim.run(scene, tmp_path / "reference").close()
    _assert_same_result(tmp_path / "aborted", tmp_path / "reference")
