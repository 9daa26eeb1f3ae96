"""Issue 24: the output fails under a run (a full disk, a read-only or wrong output path,
result.h5 deleted or replaced while the run writes it). Each ends in one line and a documented
exit status (2 before the run starts, 4 once it runs), nothing already written is lost, and the
run continues bit for bit once the fault is mended."""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from faultkit import (
    assert_invalid_input,
    assert_same_result,
    checkpoint_frame,
    jellysim_run,
    one_line,
    plain_frames,
    run_command,
    written_frames,
)

# About 117 kB a frame for 40 chains of 60 particles (10.6 MB in 91 frames), and about a tenth
# more for brown-jelly's four oral arms, which take the shared 60 particles too.
HEAVY = [
    "duration=3", "fps=30", "tentacles.count=40", "tentacles.particles=60",
    "solver.checkpoint_every=10",
]  # fmt: skip
# Two small chains, many substeps: long enough to act on the file while the run writes it.
# brown-jelly's four oral arms (5 MPa) would take three times the tentacles' substeps: as soft as
# the tentacles, and 20 s instead of 60 s, the run costs what the one-group 60 s scene did.
# A checkpoint every 200 frames: the writer also flushes each 32 frames (BATCH_FRAMES), so frames
# past the last checkpoint reach the disk by frame count, not by wall time. With a checkpoint
# every 10 frames, every flush was a checkpoint's, and seeing frames past one was a race (a
# clean-clone CI run lost it: the run ended first).
LONG = [
    "duration=20", "fps=30", "tentacles.count=2", "tentacles.particles=20",
    "tentacles.oral_arms.youngs_modulus=100", "solver.checkpoint_every=200",
    "solver.dt_safety=0.01",
]  # fmt: skip


def _mount_tmpfs(where: Path, options: str) -> bool:
    """Mount a tmpfs at ``where`` (root on Linux); False where this machine does not allow it."""
    if os.geteuid() != 0:
        return False
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(where)], capture_output=True
    )
    return done.returncode == 0


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A 32 MiB file system (empty: the run's estimate of its 17 MiB passes)."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if not _mount_tmpfs(disk, "size=32m"):
        pytest.skip("cannot mount a tmpfs here (needs root); the injected ENOSPC test stands in")
    try:
        yield disk
    finally:
        subprocess.run(["umount", "-l", str(disk)], check=False)


def _fill(disk: Path, leave: int) -> None:
    """Another program takes the disk's space but ``leave`` bytes."""
    free = shutil.disk_usage(disk).free
    with open(disk / "filler", "wb") as filler:
        filler.write(b"\0" * max(0, free - leave))


@pytest.fixture(scope="module")
def heavy_reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("heavy")
    done = jellysim_run(out, HEAVY, "--force")
    assert done.returncode == 0, done.stderr
    return out


def _assert_stopped_by_the_output(done: subprocess.CompletedProcess[str], what: str) -> str:
    assert done.returncode == 4, done.stderr
    line = one_line(done.stderr)
    assert what in line, line
    return line


def _resume_after(out: Path, line: str, reference: Path) -> None:
    """The stopped run continues as its line says, and equals the uninterrupted one."""
    frames = plain_frames(out / "result.h5")
    assert frames >= 1 and f"frames 0-{frames - 1} are written" in line, line
    if checkpoint_frame(out) is not None:
        assert "--resume'" in line, line
        done = jellysim_run(out, HEAVY, "--resume")
    else:
        assert "again with --force" in line, line
        done = jellysim_run(out, HEAVY, "--force")
    assert done.returncode == 0, done.stderr
    assert_same_result(out, reference)


def test_a_full_disk_stops_the_run_in_a_sentence(small_disk: Path, heavy_reference: Path) -> None:
    """Another program fills the disk while the run writes: the writer sees it before it writes
    a batch that would not fit."""
    out = small_disk / "run"
    process = subprocess.Popen(
        run_command(out, HEAVY), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    deadline = time.monotonic() + 300
    while written_frames(out) < 2:
        assert process.poll() is None, "the run ended before the disk filled"
        assert time.monotonic() < deadline
        time.sleep(0.01)
    _fill(small_disk, 3 * 2**20)
    stdout, stderr = process.communicate(timeout=300)
    done = subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)
    line = _assert_stopped_by_the_output(done, "the disk is full")
    (small_disk / "filler").unlink()
    _resume_after(out, line, heavy_reference)


def test_the_disks_own_refusal_leaves_the_last_flush(
    small_disk: Path, heavy_reference: Path
) -> None:
    """The free space the writer checks is gone when it writes (another program took it
    meanwhile): the disk it reserves for each batch before writing it is refused, and the file
    stays as its last flush wrote it."""
    _fill(small_disk, 8 * 2**20)
    out = small_disk / "run"
    done = jellysim_run(out, HEAVY, fault="free-space-lies")
    line = _assert_stopped_by_the_output(done, "No space left on device")
    (small_disk / "filler").unlink()
    _resume_after(out, line, heavy_reference)


def test_an_injected_enospc_leaves_the_last_flush(tmp_path: Path, heavy_reference: Path) -> None:
    """A write that fails inside HDF5 (ENOSPC injected at the third flush, after the batch's
    datasets are written to HDF5's caches; also where no tmpfs can be mounted): the file is let
    go without HDF5 writing its half-updated index, so it stays as its last flush wrote it."""
    out = tmp_path / "run"
    done = jellysim_run(out, HEAVY, fault="enospc-at:3")
    line = _assert_stopped_by_the_output(done, "No space left on device")
    _resume_after(out, line, heavy_reference)


def test_a_read_only_output_is_refused_before_the_run(tmp_path: Path) -> None:
    disk = tmp_path / "read-only"
    disk.mkdir()
    if not _mount_tmpfs(disk, "ro,size=1m"):
        if os.geteuid() == 0:
            pytest.skip("cannot mount a read-only tmpfs here, and root writes anywhere")
        disk.chmod(0o555)
    for out in (disk, disk / "run"):
        done = jellysim_run(out, ["duration=0.1"])
        assert_invalid_input(done)
        assert "not writable" in done.stderr, done.stderr
    subprocess.run(["umount", "-l", str(disk)], check=False, capture_output=True)


def test_an_output_path_that_is_a_file_is_refused(tmp_path: Path) -> None:
    taken = tmp_path / "taken"
    taken.write_text("not a folder")
    done = jellysim_run(taken, ["duration=0.1"])
    assert_invalid_input(done)
    assert "is not a folder" in done.stderr
    assert taken.read_text() == "not a folder"


def _start_and_wait(out: Path) -> tuple[subprocess.Popen[str], int]:
    """Start the LONG run; return once it has a checkpoint and frames past it on disk."""
    process = subprocess.Popen(
        run_command(out, LONG), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    deadline = time.monotonic() + 300
    while True:
        assert process.poll() is None, "the run ended before the test could act"
        assert time.monotonic() < deadline
        seen = written_frames(out)
        checkpoint = checkpoint_frame(out)
        if checkpoint is not None and seen > checkpoint + 1:
            return process, seen
        time.sleep(0.01)


def test_a_result_deleted_while_the_run_writes_it_is_written_back(tmp_path: Path) -> None:
    out = tmp_path / "run"
    process, seen = _start_and_wait(out)
    (out / "result.h5").unlink()
    _, stderr = process.communicate(timeout=300)
    assert process.returncode == 4, stderr
    line = one_line(stderr)
    assert "result.h5 was deleted while this run wrote it; written back" in line, line
    assert plain_frames(out / "result.h5") >= seen
    assert "--resume'" in line
    done = jellysim_run(out, LONG, "--resume")
    assert done.returncode == 0, done.stderr
    reference = tmp_path / "reference"
    assert jellysim_run(reference, LONG).returncode == 0
    assert_same_result(out, reference)


def test_a_result_replaced_while_the_run_writes_it_is_left_and_saved_beside(
    tmp_path: Path,
) -> None:
    out = tmp_path / "run"
    process, seen = _start_and_wait(out)
    other = tmp_path / "other.h5"
    other.write_bytes(b"someone else's file")
    os.replace(other, out / "result.h5")
    _, stderr = process.communicate(timeout=300)
    assert process.returncode == 4, stderr
    line = one_line(stderr)
    assert "replaced by another file" in line and "result.h5.saved" in line, line
    assert (out / "result.h5").read_bytes() == b"someone else's file"
    assert plain_frames(out / "result.h5.saved") >= seen
