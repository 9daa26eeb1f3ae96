"""The result store: ``result.h5`` (layout in DESIGN §3), written frame by frame in HDF5 SWMR mode.

Frames are appended in batches, each flushed to disk before its frames count as written, so a
run killed at any moment (SIGKILL included) leaves a file holding every reported frame. The
length of ``time`` is the number of frames written (it is extended last in each batch); other
per-frame datasets of a killed run may hold a few rows more, which readers ignore. A file
whose writer was killed still carries HDF5's "open for writing" flag: jellysim's own reader
opens it (in SWMR read mode); other tools need ``h5clear -s result.h5`` (Debian package
hdf5-tools) first, or a ``jellysim run --resume``, which rewrites it cleanly.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from jellysim.errors import InputError
from jellysim.fields import Dataset

RESULT_FILE = "result.h5"


def frame_datasets(tentacles: int, particles: int, margin_points: int) -> list[Dataset]:
    return [
        Dataset("time", (), "s"),
        Dataset("tentacles/position", (tentacles, particles, 3), "m"),
        Dataset("tentacles/velocity", (tentacles, particles, 3), "m/s"),
        Dataset("tentacles/constraint_error", (), "1"),
        Dataset("tentacles/projection_iterations", (), "1", np.int32),
        Dataset("bell/rim", (tentacles, 3), "m"),
        Dataset("bell/rim_velocity", (tentacles, 3), "m/s"),
        Dataset("bell/margin", (margin_points, 3), "m"),
    ]


class ResultWriter:
    """Appends frames to ``result.h5`` in SWMR mode.

    Frames are buffered and written in batches (every ``batch_frames`` frames or
    ``batch_seconds`` of wall time, and on :meth:`flush`); ``frames`` counts those flushed to
    disk, which are the ones reported as written.
    """

    def __init__(
        self,
        path: Path,
        datasets: list[Dataset],
        attributes: dict[str, Any],
        initial: dict[str, np.ndarray] | None = None,
        batch_frames: int = 32,
        batch_seconds: float = 1.0,
        static: dict[str, tuple[np.ndarray, str]] | None = None,
        links: dict[str, str] | None = None,
    ) -> None:
        """Create the file (replacing one there), optionally starting with ``initial`` frames.

        ``static`` datasets (path: (array, units)) are written once; ``links`` (path: target)
        name a per-frame dataset again (an HDF5 hard link: no second copy).
        """
        self.path = path
        temporary = path.with_name(path.name + ".tmp")
        f = h5py.File(temporary, "w", libver="latest")
        try:
            for spec in datasets:
                data = None if initial is None else initial[spec.path]
                rows = 0 if data is None else data.shape[0]
                frame_bytes = np.dtype(spec.dtype).itemsize * int(np.prod(spec.frame_shape))
                chunk_rows = max(1, min(64, 2**20 // max(1, frame_bytes)))
                ds = f.create_dataset(
                    spec.path,
                    shape=(rows, *spec.frame_shape),
                    maxshape=(None, *spec.frame_shape),
                    chunks=(chunk_rows, *spec.frame_shape),
                    dtype=spec.dtype,
                    data=data,
                )
                ds.attrs["units"] = spec.units
            for name, (array, units) in (static or {}).items():
                f.create_dataset(name, data=array)
                f[name].attrs["units"] = units
            for name, target in (links or {}).items():
                f[name] = f[target]
            for key, value in attributes.items():
                f.attrs[key] = value
            f.swmr_mode = True
            os.replace(temporary, path)  # only now visible, already in SWMR mode (open files move)
        except BaseException:
            f.close()
            temporary.unlink(missing_ok=True)
            raise
        self._file = f
        self._datasets = {spec.path: self._file[spec.path] for spec in datasets}
        self._buffer: dict[str, list[Any]] = {name: [] for name in self._datasets}
        self._batch_frames = batch_frames
        self._batch_seconds = batch_seconds
        self._last_flush = time.monotonic()
        self.frames = 0 if initial is None else int(initial["time"].shape[0])

    def append(self, values: dict[str, np.ndarray | float]) -> None:
        """Add one frame (every dataset); it reaches the disk with the next flush."""
        for name, buffer in self._buffer.items():
            buffer.append(np.array(values[name], copy=True))
        pending = len(self._buffer["time"])
        if (
            pending >= self._batch_frames
            or time.monotonic() - self._last_flush >= self._batch_seconds
        ):
            self.flush()

    def flush(self) -> None:
        """Write the buffered frames and flush them to disk."""
        pending = len(self._buffer["time"])
        if pending:
            start = self.frames
            # ``time`` goes last: its length is the count of written frames, so a kill in the
            # middle of a batch leaves the other datasets at least that long, never shorter.
            for name in sorted(self._datasets, key=lambda name: name == "time"):
                ds = self._datasets[name]
                ds.resize(start + pending, axis=0)
                ds[start:] = np.stack(self._buffer[name])
                self._buffer[name].clear()
                ds.flush()
            self._file.flush()
            self.frames = start + pending
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Flush what is buffered and close the file."""
        if self._file.id.valid:
            self.flush()
            self._file.close()


def _open(path: Path) -> h5py.File:
    try:
        return h5py.File(path, "r")
    except OSError:
        # A run killed while writing leaves the SWMR "open for writing" flag set.
        return h5py.File(path, "r", swmr=True)


def read_frames(path: Path, datasets: list[Dataset], count: int) -> dict[str, np.ndarray]:
    """The first ``count`` frames of every dataset (for a resume)."""
    with _open(path) as f:
        return {spec.path: f[spec.path][:count] for spec in datasets}


class Result:
    """A result opened for reading: ``with jellysim.open_result(DIR) as r: ...``.

    Arrays are read on access (F = frames written): ``time`` (F,) s; ``tentacle_positions`` and
    ``tentacle_velocities`` (F, T, P, 3) m, m/s; ``rim``, ``rim_velocity`` (F, T, 3);
    ``margin`` (F, R, 3) m. ``file`` is the open :class:`h5py.File` for anything else.
    """

    def __init__(self, folder: str | os.PathLike[str]) -> None:
        folder = Path(folder)
        path = folder / RESULT_FILE if folder.is_dir() or folder.suffix != ".h5" else folder
        if not path.is_file():
            raise InputError(
                f"no result at '{folder}': {path.name} not found (run 'jellysim run' first)"
            )
        try:
            self.file = _open(path)
        except OSError as err:
            raise InputError(f"cannot open '{path}': {err}") from None
        self.path = path
        self.folder = path.parent

    def __enter__(self) -> Result:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        self.file.close()

    def _array(self, name: str) -> np.ndarray:
        # A run killed mid-batch may leave a dataset longer than ``time``; those rows never counted.
        return np.asarray(self.file[name][: self.frames])

    @property
    def time(self) -> np.ndarray:
        return self._array("time")

    @property
    def tentacle_positions(self) -> np.ndarray:
        return self._array("tentacles/position")

    @property
    def tentacle_velocities(self) -> np.ndarray:
        return self._array("tentacles/velocity")

    @property
    def rim(self) -> np.ndarray:
        return self._array("bell/rim")

    @property
    def rim_velocity(self) -> np.ndarray:
        return self._array("bell/rim_velocity")

    @property
    def margin(self) -> np.ndarray:
        return self._array("bell/margin")

    @property
    def frames(self) -> int:
        return int(self.file["time"].shape[0])

    @property
    def expected_frames(self) -> int:
        return int(self.file.attrs["frames_expected"])

    @property
    def complete(self) -> bool:
        return self.frames == self.expected_frames

    @property
    def scene_text(self) -> str:
        return str(self.file.attrs["scene"])

    @property
    def scene(self) -> Any:
        from jellysim.config import load_scene
        from jellysim.config.load import parse_toml

        return load_scene(parse_toml(self.scene_text, str(self.path)))


def open_result(folder: str | os.PathLike[str]) -> Result:
    """Open the result in ``folder`` (or a ``result.h5`` path) for reading."""
    return Result(folder)
