"""A run killed inside a flush can leave a dataset's new extent on disk without the index
entries of its new chunks: HDF5 writes a flush's records in no set order, and those rows then
read as the dataset's fill value. Seen once in CI (test_kill_moments[soft-bell-SIGKILL-0.83]):
every per-frame dataset 25 rows long, ``time``'s last five rows 0, so the frames were counted
25 where 20 had been written. The writer now grows ``time`` in a flush of its own after the
other datasets' rows are on disk, with NaN as its fill value, and readers count the frames up to
the first ``time`` that is NaN or not later than the one before (``io.result.frames_written``;
docs/results.md). Here that state is made by hand: the datasets extended with no rows written."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from faultkit import assert_same_result, plain_frames

import jellysim
from jellysim import fields


class _Interrupt(Exception):
    pass


OVERRIDES = {
    "duration": 1.0,
    "tentacles.count": 2,
    "tentacles.particles": 12,
    "solver.checkpoint_every": 4,
}


def _extend_unwritten(path: Path, rows: int, time_fill: float | None) -> None:
    """Grow every per-frame dataset by ``rows`` rows that no chunk holds (the fill value); with
    ``time_fill``, write it into ``time``'s new rows (an older file's fill value, 0)."""
    with h5py.File(path, "r+") as f:
        for field in fields.FIELDS:
            if field.per_frame and field.path in f:
                ds = f[field.path]
                ds.resize(ds.shape[0] + rows, axis=0)
        if time_fill is not None:
            f[fields.TIME.path][-rows:] = time_fill


@pytest.mark.parametrize("time_fill", [None, 0.0], ids=["nan-fill", "zero-fill"])
def test_rows_a_killed_flush_did_not_finish_are_not_frames(
    tmp_path: Path, time_fill: float | None
) -> None:
    scene = jellysim.load_scene("brown-jelly", OVERRIDES)

    def abort(simulation: jellysim.Simulation) -> None:
        if simulation.frame == 14:
            raise _Interrupt

    out = tmp_path / "killed"
    with pytest.raises(_Interrupt):
        jellysim.run(scene, out, observers=[abort])
    result = out / "result.h5"
    _extend_unwritten(result, 5, time_fill)
    with h5py.File(result, "r") as f:
        times = f[fields.TIME.path][:]
    assert times.shape[0] == 19 and np.all(np.diff(times[:14]) > 0)
    assert np.all(np.isnan(times[14:])) if time_fill is None else np.all(times[14:] == 0.0)

    assert plain_frames(result) == 14  # the rule docs/results.md gives plain HDF5 readers
    with jellysim.open_result(out) as r:
        assert r.frames == 14 and r.time.shape == (14,)
    with jellysim.run(scene, out, resume=True) as r:
        assert r.frames == scene.frame_count
    jellysim.run(scene, tmp_path / "reference").close()
    assert_same_result(out, tmp_path / "reference")


def test_time_grows_after_the_other_datasets_and_fills_with_nan(tmp_path: Path) -> None:
    """The writer's order: in each batch ``time`` is resized after every other dataset's rows
    were written and flushed (a second flush), and its unwritten rows read NaN."""
    scene = jellysim.load_scene("brown-jelly", {**OVERRIDES, "duration": 0.2})
    calls: list[str] = []
    original = h5py.Dataset.resize

    def resize(self: h5py.Dataset, size: int, axis: int | None = None) -> None:
        calls.append(self.name)
        original(self, size, axis)

    flushes: list[int] = []
    original_flush = h5py.File.flush

    def flush(self: h5py.File) -> None:
        flushes.append(len(calls))
        original_flush(self)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(h5py.Dataset, "resize", resize)
        patch.setattr(h5py.File, "flush", flush)
        jellysim.run(scene, tmp_path / "run").close()
    time_name = "/" + fields.TIME.path.lstrip("/")
    assert calls.count(time_name) >= 1
    for k, name in enumerate(calls):
        if name == time_name:
            # every dataset of the batch resized before it, and a flush between them
            assert k > 0 and calls[k - 1] != time_name
            assert k in flushes
    with h5py.File(tmp_path / "run" / "result.h5", "r") as f:
        assert np.isnan(f[fields.TIME.path].fillvalue)
