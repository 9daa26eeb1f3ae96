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
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from jellysim import fields
from jellysim.errors import InputError
from jellysim.fields import Dataset, Field

RESULT_FILE = "result.h5"

# The writer holds frames in memory until this many are buffered or this much wall time has
# passed since the last flush.
BATCH_FRAMES = 32
BATCH_SECONDS = 1.0

# Which frames to read: one (int), a slice (step >= 1), or increasing indices.
Frames = int | slice | Sequence[int]


def frame_datasets(tentacles: int, particles: int, margin_points: int) -> list[Dataset]:
    """The per-frame datasets of a tentacle simulation: T = ``tentacles`` chains of
    P = ``particles``, R = ``margin_points`` margin points."""
    return [
        fields.TIME.dataset(),
        fields.TENTACLE_POSITION.dataset(T=tentacles, P=particles),
        fields.TENTACLE_VELOCITY.dataset(T=tentacles, P=particles),
        fields.TENTACLE_CONSTRAINT_ERROR.dataset(),
        fields.TENTACLE_PROJECTION_ITERATIONS.dataset(),
        fields.BELL_RIM.dataset(T=tentacles),
        fields.BELL_RIM_VELOCITY.dataset(T=tentacles),
        fields.BELL_MARGIN.dataset(R=margin_points),
    ]


def frame_bytes(spec: Dataset) -> int:
    """The bytes one frame of a per-frame dataset takes."""
    return np.dtype(spec.dtype).itemsize * int(np.prod(spec.frame_shape))


def chunk_rows(spec: Dataset) -> int:
    """Frames per HDF5 chunk of a per-frame dataset: chunks of about 1 MiB, at most 64 frames.
    A chunk takes its whole size on disk as soon as its first frame is written."""
    return max(1, min(64, 2**20 // max(1, frame_bytes(spec))))


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
        batch_frames: int = BATCH_FRAMES,
        batch_seconds: float = BATCH_SECONDS,
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
                ds = f.create_dataset(
                    spec.path,
                    shape=(rows, *spec.frame_shape),
                    maxshape=(None, *spec.frame_shape),
                    chunks=(chunk_rows(spec), *spec.frame_shape),
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
        self.frames = 0 if initial is None else int(initial[fields.TIME.path].shape[0])

    def append(self, values: dict[str, np.ndarray | float]) -> None:
        """Add one frame (every dataset); it reaches the disk with the next flush."""
        for name, buffer in self._buffer.items():
            buffer.append(np.array(values[name], copy=True))
        pending = len(self._buffer[fields.TIME.path])
        if (
            pending >= self._batch_frames
            or time.monotonic() - self._last_flush >= self._batch_seconds
        ):
            self.flush()

    def flush(self) -> None:
        """Write the buffered frames and flush them to disk."""
        pending = len(self._buffer[fields.TIME.path])
        if pending:
            start = self.frames
            # ``time`` goes last: its length is the count of written frames, so a kill in the
            # middle of a batch leaves the other datasets at least that long, never shorter.
            for name in sorted(self._datasets, key=lambda name: name == fields.TIME.path):
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


# What writes each group of datasets, for the message when a result lacks one.
_WRITTEN_BY = {
    "tentacles": "tentacles are written by scenes that simulate them (tentacles.count > 0)",
    "bell": (
        "the rim and margin come with tentacles or a bell, the body with bell.model = "
        "'kinematic' (surface, centre, contraction) or 'mass-spring' (all bell datasets)"
    ),
    "fluid": "the fluid is written by MPS scenes and the mass-spring bell's tank",
    "solver": "the pressure solver's record is written by MPS scenes and the mass-spring bell",
}


class Result:
    """A result opened for reading: ``with jellysim.open_result(DIR) as r: ...``.

    Each dataset of the layout (:mod:`jellysim.fields`) has an accessor that reads it on access
    and returns it as stored (shapes, dtypes and units in each accessor; axis letters as in
    :mod:`jellysim.fields`, F = frames written). Per-frame arrays hold the frames written only
    (a run killed mid-batch may leave a few more rows, which never counted); static arrays are
    read whole. An accessor of a dataset the result does not have raises :class:`InputError`
    naming it and what writes it; :meth:`has` asks first. :meth:`read` reads any field, or a
    few frames of it; :meth:`dataset` gives the stored dataset unread; ``file`` is the open
    :class:`h5py.File` for anything else (root attributes).
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

    def has(self, field: Field) -> bool:
        """Whether the result holds ``field``."""
        return field.path in self.file

    def dataset(self, field: Field) -> h5py.Dataset:
        """``field``'s stored dataset, unread (to read parts of a large one); a per-frame one may
        hold rows past :attr:`frames` (see :meth:`read`). Raises :class:`InputError` when the
        result has no such dataset."""
        if field.path not in self.file:
            group = field.path.partition("/")[0]
            model = self.file.attrs.get("bell_model")
            scene = "" if model is None else f" (this result's bell.model = '{model}')"
            raise InputError(
                f"{self.path}: no dataset {field.path} ({field.doc}){scene}\n"
                f"{_WRITTEN_BY.get(group, 'see docs/results.md')}"
            )
        return self.file[field.path]

    def read(self, field: Field, frames: Frames | None = None) -> np.ndarray:
        """``field`` as stored: a per-frame field's frames written (F, ...), or only ``frames``
        of them (an index drops the frame axis; a slice or increasing indices keep it); a static
        field whole. Raises :class:`InputError` when the result has no such dataset, IndexError
        for a frame not written."""
        data = self.dataset(field)
        if not field.per_frame:
            if frames is not None:
                raise ValueError(f"{field.path} is written once: it has no frames to pick")
            return np.asarray(data[()])
        count = self.frames
        if frames is None:
            return np.asarray(data[:count])
        if isinstance(frames, slice):
            start, stop, step = frames.indices(count)
            if step < 1:
                raise ValueError(f"{field.path}: frames {frames} run backwards")
            return np.asarray(data[start:stop:step])
        if isinstance(frames, int | np.integer):
            index = range(count)[frames]  # IndexError past the frames written
            return np.asarray(data[index])
        picks = [range(count)[int(k)] for k in frames]
        return np.asarray(data[picks])

    @property
    def frames(self) -> int:
        """Frames written (the length of ``time``)."""
        return int(self.file[fields.TIME.path].shape[0])

    # Per-frame arrays, (F, ...).

    @property
    def time(self) -> np.ndarray:
        """(F,) float64, s: the frame times."""
        return self.read(fields.TIME)

    @property
    def tentacle_positions(self) -> np.ndarray:
        """(F, T, P, 3) float64, m: simulated tentacle particles, root first."""
        return self.read(fields.TENTACLE_POSITION)

    @property
    def tentacle_velocities(self) -> np.ndarray:
        """(F, T, P, 3) float64, m/s: their velocities."""
        return self.read(fields.TENTACLE_VELOCITY)

    @property
    def tentacle_constraint_error(self) -> np.ndarray:
        """(F,) float64, 1: the largest relative segment-length error in each frame."""
        return self.read(fields.TENTACLE_CONSTRAINT_ERROR)

    @property
    def tentacle_projection_iterations(self) -> np.ndarray:
        """(F,) int32, 1: the most length-projection iterations of a substep in each frame."""
        return self.read(fields.TENTACLE_PROJECTION_ITERATIONS)

    @property
    def rim(self) -> np.ndarray:
        """(F, T, 3) float64, m: the tentacle base points (what drove the roots)."""
        return self.read(fields.BELL_RIM)

    @property
    def rim_velocity(self) -> np.ndarray:
        """(F, T, 3) float64, m/s: their velocities."""
        return self.read(fields.BELL_RIM_VELOCITY)

    @property
    def margin(self) -> np.ndarray:
        """(F, R, 3) float64, m: the bell margin as a closed polyline."""
        return self.read(fields.BELL_MARGIN)

    @property
    def bell_positions(self) -> np.ndarray:
        """(F, B, 3), m: the mass-spring bell's particles (float64), or the kinematic bell's
        surface vertices (float32, the same dataset as :attr:`bell_surface_vertices`)."""
        return self.read(fields.BELL_POSITION)

    @property
    def bell_velocities(self) -> np.ndarray:
        """(F, B, 3) float64, m/s: the mass-spring bell's particle velocities."""
        return self.read(fields.BELL_VELOCITY)

    @property
    def bell_surface_vertices(self) -> np.ndarray:
        """(F, V, 3) float32, m: the bell's smooth surface, for rendering (its triangles:
        :attr:`bell_surface_faces`)."""
        return self.read(fields.BELL_SURFACE_VERTICES)

    @property
    def bell_centre(self) -> np.ndarray:
        """(F, 3) float64, m: the bell's centre (the mass-spring bell's mean particle, the
        kinematic bell's margin centre)."""
        return self.read(fields.BELL_CENTRE)

    @property
    def bell_contraction(self) -> np.ndarray:
        """(F,) float64, 1: the fraction of the margin radius lost (0 relaxed)."""
        return self.read(fields.BELL_CONTRACTION)

    @property
    def bell_activation(self) -> np.ndarray:
        """(F,) float64, 1: the mass-spring bell's muscle activation a(t) in [0, 1]."""
        return self.read(fields.BELL_ACTIVATION)

    @property
    def fluid_positions(self) -> np.ndarray:
        """(F, N, D), m: fluid, wall and dummy particles, D = 2 or 3; float64, float32 in a
        mass-spring bell's tank."""
        return self.read(fields.FLUID_POSITION)

    @property
    def fluid_velocities(self) -> np.ndarray:
        """(F, N, D), m/s: their velocities (dtype as :attr:`fluid_positions`)."""
        return self.read(fields.FLUID_VELOCITY)

    @property
    def fluid_pressure(self) -> np.ndarray:
        """(F, N), Pa: their pressure (dtype as :attr:`fluid_positions`)."""
        return self.read(fields.FLUID_PRESSURE)

    @property
    def fluid_number_density(self) -> np.ndarray:
        """(F, N), 1: their MPS particle number density (dtype as :attr:`fluid_positions`)."""
        return self.read(fields.FLUID_NUMBER_DENSITY)

    @property
    def fluid_alive(self) -> np.ndarray:
        """(F, N) bool: False from the frame a particle left the domain."""
        return self.read(fields.FLUID_ALIVE)

    @property
    def solver_iterations(self) -> np.ndarray:
        """(F,) int32, 1: pressure-solver iterations of each frame's last step."""
        return self.read(fields.SOLVER_ITERATIONS)

    @property
    def solver_residual(self) -> np.ndarray:
        """(F,) float64, 1: that solve's relative residual."""
        return self.read(fields.SOLVER_RESIDUAL)

    @property
    def solver_steps(self) -> np.ndarray:
        """(F,) int32, 1: MPS steps in each frame."""
        return self.read(fields.SOLVER_STEPS)

    # Static arrays, written once.

    @property
    def bell_surface_faces(self) -> np.ndarray:
        """(M, 3) int32: triangles over the surface vertices, counter-clockwise seen from
        outside."""
        return self.read(fields.BELL_SURFACE_FACES)

    @property
    def bell_springs(self) -> np.ndarray:
        """(S, 2) int64: the mass-spring bell's particle pairs joined by springs."""
        return self.read(fields.BELL_SPRINGS)

    @property
    def bell_muscle(self) -> np.ndarray:
        """(S,) bool: the springs of the circular muscle."""
        return self.read(fields.BELL_MUSCLE)

    @property
    def bell_rest_positions(self) -> np.ndarray:
        """(B, 3) float64, m: the mass-spring bell's particles at rest."""
        return self.read(fields.BELL_REST_POSITION)

    @property
    def fluid_kind(self) -> np.ndarray:
        """(N,) int8: 0 fluid, 1 wall, 2 dummy."""
        return self.read(fields.FLUID_KIND)

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
    """Open the result in ``folder`` (or a ``result.h5`` path) for reading; a result that holds
    no frame (its run stopped before the first was written) is refused with InputError."""
    result = Result(folder)
    if result.frames == 0:
        result.close()
        raise InputError(
            f"'{result.path}' holds no frames: its run stopped before writing the first "
            "(run the scene again with --force)"
        )
    return result
