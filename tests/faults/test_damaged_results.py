"""Issue 24: a damaged result (a copy cut short, flipped bytes, not HDF5 at all, a killed run of
the older SWMR writer cut short) is refused in seconds by every reader (plot, render, every
export format, view): one line, exit status 2, never a hang, a traceback or wrong numbers."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from faultkit import jellysim_run

import jellysim

READERS = [
    ("plot",),
    ("render", "--quality", "draft"),
    *(("export", "--format", fmt) for fmt in ("vtk", "usd", "gltf", "obj", "ply")),
    ("view", "--no-browser"),
]
SECONDS = 20.0  # a reader that has not answered by then hangs (HDF5's SWMR retries took minutes)


@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("good")
    done = jellysim_run(out, ["duration=1", "fps=30", "tentacles.count=3"], "--force")
    assert done.returncode == 0, done.stderr
    return out


def _copy(good: Path, where: Path) -> Path:
    where.mkdir()
    shutil.copy(good / "scene.toml", where / "scene.toml")
    shutil.copy(good / "result.h5", where / "result.h5")
    return where / "result.h5"


def _assert_refused_by_every_reader(folder: Path, words: str) -> None:
    for reader in READERS:
        command, *options = reader
        start = time.monotonic()
        done = subprocess.run(
            [sys.executable, "-m", "jellysim", command, str(folder), *options],
            capture_output=True,
            text=True,
            timeout=SECONDS * 3,
            cwd=folder.parent,
        )
        took = time.monotonic() - start
        assert done.returncode == 2, (reader, done.stderr)
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in done.stderr, (reader, done.stderr)
        assert words in lines[0], (reader, lines[0])
        assert took < SECONDS, f"{reader} took {took:.1f} s to refuse"


def test_a_result_cut_short_is_refused(tmp_path: Path, good: Path) -> None:
    path = _copy(good, tmp_path / "cut")
    size = path.stat().st_size
    with open(path, "r+b") as f:
        f.truncate(size // 2)
    _assert_refused_by_every_reader(path.parent, "is truncated")


def test_a_result_that_is_not_hdf5_is_refused(tmp_path: Path, good: Path) -> None:
    path = _copy(good, tmp_path / "garbage")
    path.write_bytes(os.urandom(4096))
    _assert_refused_by_every_reader(path.parent, "not an HDF5 file")


def test_flipped_bytes_in_a_frame_are_an_error_not_wrong_numbers(
    tmp_path: Path, good: Path
) -> None:
    """Chunks carry Fletcher-32 checksums: a flipped byte in the tentacles' positions is
    refused where it is read, by the Python API and by every reader."""
    path = _copy(good, tmp_path / "flipped")
    with h5py.File(path, "r") as f:
        offset = f["tentacles/position"].id.get_chunk_info(0).byte_offset
    with open(path, "r+b") as f:
        f.seek(offset + 100)
        byte = f.read(1)
        f.seek(offset + 100)
        f.write(bytes([byte[0] ^ 0xFF]))
    with jellysim.open_result(path.parent) as r:
        with pytest.raises(jellysim.InputError, match="is damaged"):
            r.tentacle_positions  # noqa: B018 (the read is the test)
        assert np.all(np.isfinite(r.time))  # the undamaged datasets still read
    _assert_refused_by_every_reader(path.parent, "damaged")


def test_a_killed_swmr_result_cut_short_is_refused_in_seconds(tmp_path: Path) -> None:
    """Results of killed runs written by jellysim before this writer carry SWMR's "open for
    writing" flag, and SWMR read mode retried a truncated one for minutes."""
    path = tmp_path / "old" / "result.h5"
    path.parent.mkdir()
    writer = subprocess.Popen(
        [
            sys.executable, "-c",
            "import h5py, sys, time\n"
            f"f = h5py.File({str(path)!r}, 'w', libver='latest')\n"
            "d = f.create_dataset('time', (0,), maxshape=(None,), chunks=(64,), dtype='f8')\n"
            "f.swmr_mode = True\n"
            "for i in range(100000):\n"
            "    d.resize(i + 1, axis=0); d[i] = i; f.flush()\n"
            "    if i == 1000: print('ready', flush=True)\n"
            "time.sleep(60)\n",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    assert writer.stdout is not None and writer.stdout.readline() == "ready\n"
    writer.kill()
    writer.communicate()
    with pytest.raises(OSError, match="already open for write"):
        h5py.File(path, "r")
    with h5py.File(path, "r", swmr=True) as f:
        assert f["time"].shape[0] > 1000  # the flagged file opens in SWMR mode
    with open(path, "r+b") as f:
        f.truncate(path.stat().st_size // 2)
    start = time.monotonic()
    with pytest.raises(jellysim.InputError, match="is truncated"):
        jellysim.open_result(path)
    assert time.monotonic() - start < 5.0
