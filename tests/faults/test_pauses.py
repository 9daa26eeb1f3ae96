"""Issue 24: SIGKILL at the exact moments that matter most, reached by pausing the run there
(tests/faults/runner.py): in the middle of a batch's dataset writes, after every dataset of a
batch is written but before HDF5 flushes, while a checkpoint is being written, and as a resume
or --force gives result.h5 its new file. Each time plain h5py opens the file, it holds the frames
of the last flush, its XDMF sidecar (if any) fits it, and --resume is bit for bit."""

from __future__ import annotations

import signal
import subprocess
from pathlib import Path

import pytest
from faultkit import (
    assert_same_result,
    checkpoint_frame,
    jellysim_run,
    plain_frames,
    run_command,
    sidecar_frames,
)

import jellysim
from jellysim.export import export

# 91 frames written in batches of a second's wall time at most; checkpoints every 10 frames.
OVERRIDES = [
    "duration=3", "fps=30", "tentacles.count=2", "tentacles.particles=20",
    "solver.checkpoint_every=10", "solver.dt_safety=0.02",
]  # fmt: skip


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("reference")
    done = jellysim_run(out, OVERRIDES, "--force")
    assert done.returncode == 0, done.stderr
    return out


def _kill_when_paused(out: Path, fault: str, *extra: str, overrides: list[str] = OVERRIDES) -> str:
    process = subprocess.Popen(
        run_command(out, overrides, *extra, fault=fault),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stderr is not None
        line = process.stderr.readline()  # the runner's PAUSED line
        assert line.startswith("PAUSED"), line + process.stderr.read()
        process.send_signal(signal.SIGKILL)
        process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == -signal.SIGKILL
    return line


@pytest.mark.parametrize("fault", ["pause-in-write:3", "pause-in-flush:3", "pause-in-checkpoint:2"])
def test_sigkill_during_a_write_leaves_the_last_flush(
    tmp_path: Path, reference: Path, fault: str
) -> None:
    out = tmp_path / "killed"
    _kill_when_paused(out, fault)
    frames = plain_frames(out / "result.h5")
    assert frames >= 1
    checkpoint = checkpoint_frame(out)
    if fault.startswith("pause-in-checkpoint"):
        # The second checkpoint was being written: the first stays, whole.
        assert checkpoint == 10
        assert (out / "checkpoint.npz.tmp").exists()
    assert checkpoint is not None and checkpoint < frames
    done = jellysim_run(out, OVERRIDES, "--resume")
    assert done.returncode == 0, done.stderr
    assert_same_result(out, reference)


@pytest.mark.parametrize("again", ["--resume", "--force"])
def test_sigkill_as_result_h5_is_replaced_leaves_no_sidecar_of_the_old_file(
    tmp_path: Path, reference: Path, again: str
) -> None:
    """A resume rewrites result.h5 with the frames up to its checkpoint, --force (here of
    another scene: three tentacles, not two) with none: killed the moment the new file has
    taken the name, the folder holds no sidecar of the old file's frames or shapes."""
    out = tmp_path / "killed"
    _kill_when_paused(out, "pause-in-checkpoint:2")  # frames 0-20 flushed, checkpoint at 10
    before = plain_frames(out / "result.h5")
    # The killed run's sidecar, made to list every frame (a run rewrites it at some flushes).
    with jellysim.open_result(out) as result:
        export(result, "xdmf")
    assert sidecar_frames(out) == before
    checkpoint = checkpoint_frame(out)
    assert checkpoint is not None and checkpoint + 1 < before
    other = OVERRIDES if again == "--resume" else [*OVERRIDES, "tentacles.count=3"]
    line = _kill_when_paused(out, "pause-after-replace:result.h5", again, overrides=other)
    assert "result.h5" in line
    frames = plain_frames(out / "result.h5")
    assert frames == (checkpoint + 1 if again == "--resume" else 0)
    sidecar_frames(out)  # none, or one that fits the new file
    done = jellysim_run(out, OVERRIDES, again)
    assert done.returncode == 0, done.stderr
    assert_same_result(out, reference)
