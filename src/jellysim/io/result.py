"""The result store: ``result.h5`` (layout in DESIGN §3), written frame by frame.

Frames are appended in batches, each flushed to disk before its frames count as written. The
file is plain HDF5 (the 1.8 format, neither SWMR nor HDF5's file lock: the folder's writer lock
keeps other writers out), so a run killed at any moment (SIGKILL included) leaves a file that
h5py, xarray, ParaView and every HDF5 tool open as it is, holding every reported frame. Between
flushes HDF5 keeps the file's index in memory, so the file on disk stays as the last flush left
it. ``time`` is extended last in each batch and a reader counts the frames every per-frame
dataset holds (:attr:`Result.frames`). Chunks carry Fletcher-32 checksums, so a damaged chunk
is an error, never silently wrong numbers. Disk full, a read-only folder, or ``result.h5``
deleted or replaced while the run writes it stop the run with :class:`OutputError`, the frames
already on disk kept (a deleted file is written back from the run's open copy).

Every axis is named by an HDF5 dimension scale (netCDF-4's layout, written with the file:
:func:`write_dimension_scales`), so xarray and netCDF tools read the file with the dimensions of
:meth:`Result.to_xarray`; the XDMF sidecar ``result.xdmf`` beside it
(:mod:`jellysim.io.xdmf`) lets ParaView and VisIt open it as a time series.
"""

from __future__ import annotations

import ctypes
import errno
import numbers
import os
import shutil
import struct
import time
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from jellysim import fields
from jellysim.config.schema import DEFAULT_GROUP
from jellysim.errors import InputError, OutputError
from jellysim.fields import Dataset, Field
from jellysim.io.xdmf import SidecarCache, write_xdmf

RESULT_FILE = "result.h5"

# The writer holds frames in memory until this many are buffered or this much wall time has
# passed since the last flush.
BATCH_FRAMES = 32
BATCH_SECONDS = 1.0

# Which frames to read: one (int), a slice (step >= 1), or increasing indices.
Frames = int | slice | Sequence[int]

# The HDF5 format written: 1.8's, which every HDF5 reader of the last fifteen years opens and
# which carries no "open for writing" flag that a killed writer would leave set.
LIBVER = ("earliest", "v108")

# The XDMF sidecar is rewritten at a flush only once this many times its last write's duration
# has passed since that write.
SIDECAR_PAUSE = 20.0

# Room kept free on the output's file system beyond a batch's own bytes (HDF5's index, the
# checkpoint): a batch that would not fit with this margin is not started.
FREE_SPACE_MARGIN = 4 * 2**20
# Disk reserved for a batch beyond its frames' bytes: HDF5's index grows a little with each.
RESERVE_MARGIN = 2**20


# Dimension names of Result.to_xarray for the axis letters of jellysim.fields.
DIMENSIONS = {
    "T": "tentacle",
    "P": "particle",
    "R": "margin_point",
    "B": "bell_particle",
    "V": "vertex",
    "M": "triangle",
    "S": "spring",
    "N": "fluid_particle",
    "D": "dimension",
    "H": "height_probe",
    "K": "pressure_probe",
}


def _dimension(field: Field, axis: str | int) -> str:
    """The xarray dimension of one axis of ``field``: a named length, or for a fixed one the
    triangle's ``corner``, a spring's ``end``, otherwise ``xyz``."""
    if isinstance(axis, str):
        return DIMENSIONS[axis]
    if "M" in field.axes:
        return "corner"
    if "S" in field.axes:
        return "end"
    return "xyz"


def dimension_names(field: Field) -> tuple[str, ...]:
    """The named dimensions of ``field``'s dataset: ``time`` first for a per-frame field, then
    one per axis (:data:`DIMENSIONS`); the same in ``result.h5``'s dimension scales and in
    :meth:`Result.to_xarray`."""
    names = tuple(_dimension(field, axis) for axis in field.axes)
    return ("time", *names) if field.per_frame else names


# A kinematic bell's bell/position is an HDF5 hard link to bell/surface_vertices (one dataset,
# DESIGN §3): it has the surface's dimensions.
SHARED_DATASETS = {fields.BELL_POSITION.path: fields.BELL_SURFACE_VERTICES}

# The netCDF-4 convention for a dimension without a coordinate variable: a dataset of the
# dimension's length, no data stored, marked by this NAME (what netCDF-C writes; h5netcdf and
# netCDF-C read such a dataset as a dimension only).
NOT_A_VARIABLE = "This is a netCDF dimension but not a netCDF variable.%10d"


def write_dimension_scales(f: h5py.File, paths: Sequence[str]) -> None:
    """Name the axes of the datasets at ``paths`` with HDF5 dimension scales (the netCDF-4
    layout), so xarray (h5netcdf) and netCDF tools read ``result.h5`` with named dimensions:
    ``time`` (s) is the time axis's scale and coordinate, ``xyz`` a coordinate labelled "x",
    "y", "z", every other dimension a root dataset of its length that stores no data. Written
    when the file is created: a killed run's file has them."""
    lengths: dict[str, int] = {}
    attached: list[tuple[h5py.Dataset, tuple[str, ...]]] = []
    for path in paths:
        field = fields.BY_PATH[path]
        ds = f[path]
        names = dimension_names(field)
        if field is not fields.TIME:
            attached.append((ds, names))
        ds.attrs["long_name"] = field.doc
        for name, length in zip(names, ds.shape, strict=True):
            if name != "time" and lengths.setdefault(name, length) != length:
                raise ValueError(f"{path}: dimension {name} of {length}, elsewhere {lengths[name]}")
    f[fields.TIME.path].make_scale("time")
    for name, length in lengths.items():
        if name == "xyz":
            scale = f.create_dataset(
                name, data=np.array(["x", "y", "z"], dtype=h5py.string_dtype())
            )
            scale.make_scale(name)
        else:
            scale = f.create_dataset(name, shape=(length,), dtype=np.float32)
            scale.make_scale(NOT_A_VARIABLE % length)
    for ds, names in attached:
        for axis, name in enumerate(names):
            ds.dims[axis].attach_scale(f[name])


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
    """Frames per HDF5 chunk of a per-frame dataset: one. A chunk is then written once, whole,
    in the flush that adds its frame, and never rewritten: HDF5 rewrites a chunk of several
    frames in place each time one of its frames is added, so a run killed during that rewrite
    lost the chunk's earlier frames, already reported written (their checksums failed on
    resume; seen once in tests/faults/test_kill_moments.py)."""
    return 1


_LIBC = ctypes.CDLL(None, use_errno=True)
_FALLOCATE = getattr(_LIBC, "fallocate", None)  # Linux
if _FALLOCATE is not None:
    _FALLOCATE.argtypes = (ctypes.c_int, ctypes.c_int, ctypes.c_int64, ctypes.c_int64)
FALLOC_FL_KEEP_SIZE = 1


def _reserve(descriptor: int, length: int) -> None:
    """Allocate ``length`` bytes of disk past the end of the open file, its size unchanged
    (Linux ``fallocate`` with FALLOC_FL_KEEP_SIZE), so the writes that follow cannot meet a
    full disk halfway: HDF5, failing a write in a flush, goes on to write an index that points
    at the data it could not write. Raises OSError (ENOSPC) when the disk has no room; where
    the file system cannot reserve, nothing is done."""
    if _FALLOCATE is None:
        return
    end = os.fstat(descriptor).st_size
    if _FALLOCATE(descriptor, FALLOC_FL_KEEP_SIZE, end, length) != 0:
        number = ctypes.get_errno()
        if number in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
            raise OSError(number, os.strerror(number))


def _os_reason(err: OSError | RuntimeError) -> str:
    """What the system said, for a sentence; HDF5's own errors name the errno in their text."""
    if isinstance(err, OSError) and err.errno is not None:
        return os.strerror(err.errno)
    text = str(err)
    for number in (errno.ENOSPC, errno.EROFS, errno.EDQUOT, errno.EIO, errno.EACCES):
        if f"errno = {number}," in text or os.strerror(number) in text:
            return os.strerror(number)
    return text


class ResultWriter:
    """Appends frames to ``result.h5``.

    Frames are buffered and written in batches (every ``batch_frames`` frames or
    ``batch_seconds`` of wall time, and on :meth:`flush`); ``frames`` counts those flushed to
    disk, which are the ones reported as written. A fault of the output (disk full, not
    writable, the file deleted or replaced) raises :class:`OutputError` from :meth:`flush`;
    the file then keeps the frames of the last good flush and is written no more.

    Beside ``result.h5`` the writer keeps ``result.xdmf`` (:mod:`jellysim.io.xdmf`), the XDMF
    description through which ParaView and VisIt open the result: written with the file's first
    frames (with the file, for a resume's), again at flushes (see :meth:`_write_sidecar`) and on
    :meth:`close`, always whole. Whenever
    ``result.xdmf`` is there, it lists frames the ``result.h5`` beside it holds, with its
    shapes: the old sidecar is removed before a new file takes the name.
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
        self.frames = 0 if initial is None else int(initial[fields.TIME.path].shape[0])
        sidecar = path.with_suffix(".xdmf")
        temporary = path.with_name(path.name + ".tmp")
        try:
            f = h5py.File(temporary, "w", libver=LIBVER, locking=False)
        except OSError as err:
            raise self._fault(f"cannot create {temporary.name} ({_os_reason(err)})") from None
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
                    fletcher32=True,
                    # a row whose chunk a killed flush did not index reads as NaN, not a time
                    fillvalue=np.nan if spec.path == fields.TIME.path else None,
                )
                ds.attrs["units"] = spec.units
                for key, value in spec.attributes:
                    ds.attrs[key] = value
            for name, (array, units) in (static or {}).items():
                f.create_dataset(name, data=array, fletcher32=array.size > 0)
                f[name].attrs["units"] = units
            for name, target in (links or {}).items():
                f[name] = f[target]
            write_dimension_scales(f, [spec.path for spec in datasets] + list(static or {}))
            for key, value in attributes.items():
                f.attrs[key] = value
            f.flush()
            # The sidecar of the file being replaced goes first: killed between the two, the
            # folder holds the old file without a sidecar, never the new one with the old's
            # (a resume's file holds fewer frames, a --force's other shapes).
            sidecar.unlink(missing_ok=True)
            os.replace(temporary, path)  # only now visible, complete (open files move)
        except OSError as err:
            _abandon(f)
            temporary.unlink(missing_ok=True)
            raise self._fault(f"cannot write {path.name} ({_os_reason(err)})") from None
        except BaseException:
            f.close()
            temporary.unlink(missing_ok=True)
            raise
        self._file = f
        self._sidecar = sidecar
        self._sidecar_frames = -1  # the frames the sidecar on disk lists
        self._sidecar_bytes = 0
        self._sidecar_seconds = 0.0  # what its last write took
        self._sidecar_at = 0.0
        self._sidecar_cache = SidecarCache()  # the texts of frames already listed
        try:
            self._write_sidecar()
        except OutputError:
            f.close()
            raise
        self._descriptor = int(f.id.get_vfd_handle())
        self._datasets = {spec.path: self._file[spec.path] for spec in datasets}
        self._frame_bytes = sum(frame_bytes(spec) for spec in datasets)
        self._buffer: dict[str, list[Any]] = {name: [] for name in self._datasets}
        self._batch_frames = batch_frames
        self._batch_seconds = batch_seconds
        self._last_flush = time.monotonic()
        self._broken = False

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

    def _write_sidecar(self, force: bool = True) -> None:
        """Write the XDMF sidecar (:mod:`jellysim.io.xdmf`) listing the frames flushed, whole
        or not at all. Unless ``force``, skipped while less than :data:`SIDECAR_PAUSE` times its
        last write's duration has passed since then, so rewriting a long run's sidecar takes at
        most a twentieth of the run's time; :meth:`close` writes it last. None of no frame:
        ``vtkXdmfReader`` crashes (SIGSEGV) on a temporal collection without grids, and on a
        document without collections."""
        if self._sidecar_frames == self.frames or self.frames == 0:
            return
        now = time.monotonic()
        if not force and now - self._sidecar_at < SIDECAR_PAUSE * self._sidecar_seconds:
            return
        try:
            self._sidecar_bytes = write_xdmf(
                self._file, self.path, self._sidecar, range(self.frames), self._sidecar_cache
            )
        except OSError as err:
            raise self._fault(f"cannot write {self._sidecar.name} ({_os_reason(err)})") from None
        self._sidecar_frames = self.frames
        self._sidecar_at = time.monotonic()
        self._sidecar_seconds = self._sidecar_at - now

    def _fault(self, what: str) -> OutputError:
        written = "no frame is" if self.frames == 0 else f"frames 0-{self.frames - 1} are"
        return OutputError(
            f"{self.path.parent}: {what}; {written} written in {self.path.name}",
            frames=self.frames,
        )

    def _check_file(self, pending: int) -> None:
        """At each flush: ``path`` must still be this file, and the disk must have room for the
        ``pending`` frames."""
        try:
            named = os.stat(self.path)
        except FileNotFoundError:
            named = None
        mine = os.fstat(self._descriptor)
        if named is None or (named.st_ino, named.st_dev) != (mine.st_ino, mine.st_dev):
            raise self._moved(named is None)
        if not pending:
            return
        free = shutil.disk_usage(self.path.parent).free
        needed = pending * self._frame_bytes + self._sidecar_bytes + FREE_SPACE_MARGIN
        if free < needed:
            raise self._fault(
                f"the disk is full ({free / 2**20:.1f} MiB free, the next {pending} frames "
                f"need {needed / 2**20:.1f} MiB with room for the index)"
            )

    def _moved(self, deleted: bool) -> OutputError:
        """``result.h5`` was deleted or replaced under the run: write the run's frames back
        (the open file still holds them) where they cannot clobber anything."""
        self._file.flush()
        target = self.path if deleted else self.path.with_name(self.path.name + ".saved")
        temporary = target.with_name(target.name + ".tmp")
        try:
            with open(f"/proc/self/fd/{self._descriptor}", "rb") as source:
                with open(temporary, "wb") as copy:
                    shutil.copyfileobj(source, copy, 2**20)
            os.replace(temporary, target)
        except OSError as err:
            temporary.unlink(missing_ok=True)
            self._broken = True
            return self._fault(
                f"{self.path.name} was {'deleted' if deleted else 'replaced'} while this run "
                f"wrote it, and its frames could not be saved again ({_os_reason(err)})"
            )
        if deleted:
            what = f"{self.path.name} was deleted while this run wrote it; written back"
        else:
            what = (
                f"{self.path.name} was replaced by another file while this run wrote it (left "
                f"as it is); the run's own result is saved as {target.name}"
            )
        self._broken = True
        return self._fault(what)

    def flush(self) -> None:
        """Write the buffered frames and flush them to disk (raises :class:`OutputError` when
        the output refuses them; the frames of earlier flushes stay on disk)."""
        if self._broken:
            raise self._fault("the output failed earlier")
        pending = len(self._buffer[fields.TIME.path])
        self._check_file(pending)
        if pending:
            try:
                _reserve(self._descriptor, pending * self._frame_bytes + RESERVE_MARGIN)
            except OSError as err:
                raise self._fault(f"cannot write the next frames ({_os_reason(err)})") from None
            start = self.frames
            try:
                # Two flushes: every other dataset's rows are on disk before ``time`` grows.
                # HDF5 writes a flush's index records in no set order, so a kill inside one
                # flush can leave a dataset's new extent on disk without its new chunks' index
                # entries (those rows read as the fill value; seen in CI as a result whose
                # last five times read 0): ``time``'s rows then read NaN, its fill value, and
                # readers count the frames up to the first of them (:func:`frames_written`).
                for last in (False, True):
                    for name, ds in self._datasets.items():
                        if (name == fields.TIME.path) != last:
                            continue
                        ds.resize(start + pending, axis=0)
                        ds[start:] = np.stack(self._buffer[name])
                        self._buffer[name].clear()
                    self._file.flush()
            except (OSError, RuntimeError) as err:  # h5py raises either for a failed write
                # HDF5 would write its half-updated index on close: the file is left as the
                # last good flush wrote it.
                _abandon(self._file)
                self._broken = True
                raise self._fault(f"cannot write the next frames ({_os_reason(err)})") from None
            self.frames = start + pending
            self._write_sidecar(force=False)
        self._last_flush = time.monotonic()

    def close(self, discard: bool = False) -> None:
        """Flush what is buffered and close the file; ``discard``: drop the frames not yet
        flushed instead (after an output fault). After a failed write: only let go of it."""
        if not self._file.id.valid:
            return
        if self._broken:
            _abandon(self._file)
            return
        if discard:
            for buffer in self._buffer.values():
                buffer.clear()
        try:
            self.flush()
            if not discard:  # after a fault the sidecar stays as its last write left it
                self._write_sidecar()
        finally:
            if self._file.id.valid and not self._broken:
                self._file.close()


def _abandon(f: h5py.File) -> None:
    """Let go of an HDF5 file without writing to it again: its descriptor is pointed at an
    anonymous file in memory first, so the close writes its half-updated index there instead
    of over the last good flush (and succeeds: a close whose writes fail leaves HDF5 to crash
    at exit)."""
    try:
        descriptor = int(f.id.get_vfd_handle())
        make = getattr(os, "memfd_create", None)
        scratch = make("abandoned-result") if make else os.open(os.devnull, os.O_RDONLY)
        try:
            os.dup2(scratch, descriptor)
        finally:
            os.close(scratch)
    except (OSError, ValueError, RuntimeError):
        pass
    try:
        f.close()
    except (OSError, RuntimeError):
        pass


# The superblock's end-of-file address: its byte offset by superblock version (HDF5 file format
# specification, "Superblock"); offsets are 8 bytes in the files h5py writes.
_EOF_OFFSET = {0: 40, 1: 44, 2: 28, 3: 28}
_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _check_not_truncated(path: Path) -> None:
    """Refuse, in a sentence, a file shorter than its own superblock says (a copy cut short):
    HDF5 would otherwise retry reading it for minutes in SWMR mode."""
    try:
        with open(path, "rb") as handle:
            head = handle.read(64)
            size = os.fstat(handle.fileno()).st_size
    except OSError as err:
        raise InputError(f"cannot read '{path}' ({_os_reason(err)})") from None
    if not head.startswith(_SIGNATURE):
        raise InputError(f"'{path}' is not a result: not an HDF5 file (damaged, or another file)")
    version = head[8]
    offset = _EOF_OFFSET.get(version)
    if offset is None or len(head) < offset + 8 or head[13 if version < 2 else 9] != 8:
        return  # a layout this check does not know: HDF5's own checks apply
    (end,) = struct.unpack_from("<Q", head, offset)
    if end > size:
        raise InputError(
            f"'{path}' is truncated: it holds {size:,} of its {end:,} bytes (a copy cut short?); "
            "copy it again, or run the scene again"
        )


def _open(path: Path) -> h5py.File:
    _check_not_truncated(path)
    # HDF5's default file locking, as plain h5py uses: one process may then open the file
    # both ways (HDF5 refuses a second open with other locking flags). The writer takes no lock.
    try:
        return h5py.File(path, "r")
    except OSError as err:
        if "already open for write" not in str(err):
            raise
        # A killed run of an older jellysim (which wrote in SWMR mode) left SWMR's "open for
        # writing" flag set: SWMR read mode opens that file (its length was checked above).
        return h5py.File(path, "r", swmr=True)


def frames_written(f: h5py.File) -> int:
    """The frames a result holds: the rows every per-frame dataset has, up to the first row of
    ``time`` that is not a time later than the row before it (NaN, ``time``'s fill value, or
    0, an older file's). The writer grows ``time`` in a flush of its own after the other
    datasets' rows are on disk, so a run killed mid-batch leaves the others a few rows longer
    and may leave ``time`` rows its flush did not finish, which read as the fill value
    (docs/results.md, "Killed runs and resume")."""
    rows = min(
        (int(f[field.path].shape[0]) for field in fields.FIELDS
         if field.per_frame and field.path in f),
        default=0,
    )  # fmt: skip
    if rows == 0 or fields.TIME.path not in f:
        return rows
    times = np.asarray(f[fields.TIME.path][:rows], dtype=np.float64)
    good = np.isfinite(times)
    good[1:] &= np.diff(times) > 0.0
    return rows if good.all() else int(np.argmin(good))


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
    "probes": "probes are written by fluid-only scenes with [probes] height or pressure",
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
            raise InputError(
                f"'{path}' does not open as a result ({err}): it is damaged or not a result"
            ) from None
        self.path = path
        self.folder = path.parent
        self._frames: int | None = None

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
        """Close the file (a ``with`` block does it on leaving)."""
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
        try:
            return self._read(field, frames)
        except OSError as err:
            raise InputError(
                f"'{self.path}' is damaged: {field.path} does not read ({err}); "
                "run the scene again (or copy the result again)"
            ) from None

    def _read(self, field: Field, frames: Frames | None) -> np.ndarray:
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
        """Frames written (:func:`frames_written`)."""
        if self._frames is None:
            self._frames = frames_written(self.file)
        return self._frames

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
    def tentacle_group(self) -> np.ndarray:
        """(T,) int32, 1: the group of each simulated tentacle, an index into
        :attr:`tentacle_groups`. A result written before tentacle groups (no
        ``tentacles/group``) has one group: all zeros."""
        if fields.TENTACLE_GROUP.path not in self.file and self.has(fields.TENTACLE_POSITION):
            count = self.dataset(fields.TENTACLE_POSITION).shape[1]
            return np.zeros(count, dtype=np.int32)
        return self.read(fields.TENTACLE_GROUP)

    @property
    def tentacle_particles(self) -> np.ndarray:
        """(T,) int32, 1: the particles of each simulated tentacle; its rows of
        :attr:`tentacle_positions` and :attr:`tentacle_velocities` beyond them are NaN. A
        result written before tentacle groups has P for every tentacle."""
        if fields.TENTACLE_PARTICLES.path not in self.file and self.has(fields.TENTACLE_POSITION):
            _, count, particles, _ = self.dataset(fields.TENTACLE_POSITION).shape
            return np.full(count, particles, dtype=np.int32)
        return self.read(fields.TENTACLE_PARTICLES)

    @property
    def probe_heights(self) -> np.ndarray:
        """(F, H) float64, m: the water depth along each height probe's line (``probes/height``;
        the probes' names in :meth:`probes`)."""
        return self.read(fields.PROBE_HEIGHT)

    @property
    def probe_pressures(self) -> np.ndarray:
        """(F, K) float64, Pa: the wall pressure at each pressure probe, the frame's mean
        (``probes/pressure``; the probes' names in :meth:`probes`)."""
        return self.read(fields.PROBE_PRESSURE)

    def probes(self) -> dict[str, tuple[np.ndarray, str]]:
        """Every probe's record by its name: ((F,) values, units), the height probes' in m,
        then the pressure probes' in Pa (``probes/height``, ``probes/pressure``); empty for a
        result without probes."""
        out: dict[str, tuple[np.ndarray, str]] = {}
        for field in (fields.PROBE_HEIGHT, fields.PROBE_PRESSURE):
            if self.has(field):
                names = np.atleast_1d(self.dataset(field).attrs["names"])
                values = self.read(field)
                for k, name in enumerate(names):
                    key = name.decode() if isinstance(name, bytes) else str(name)
                    out[key] = (values[:, k], field.units)
        return out

    @property
    def tentacle_groups(self) -> list[str]:
        """The names of the tentacle groups, in the scene's order (``tentacle_group`` indexes
        them); ``["tentacles"]`` for a one-table scene and for results written before groups."""
        names = self.file.attrs.get("tentacle_groups")
        if names is None:
            return [DEFAULT_GROUP]
        return [n.decode() if isinstance(n, bytes) else str(n) for n in np.atleast_1d(names)]

    @property
    def tentacle_flow(self) -> str:
        """The water the tentacles felt (``flow.model``): "bell" (the paper's flow relative to the
        bell; also results written before issue 26), "current", "fluid" (the simulated water)
        or "fluid-two-way" (and acting back on it)."""
        flow = self.file.attrs.get("tentacle_flow", "bell")
        return flow.decode() if isinstance(flow, bytes) else str(flow)

    @property
    def tentacle_drag(self) -> list[str]:
        """Each tentacle group's drag law, "sphere" (the paper's; also results written before
        issue 26) or "slender", in the order of :attr:`tentacle_groups`."""
        laws = self.file.attrs.get("tentacle_drag")
        if laws is None:
            return ["sphere"] * len(self.tentacle_groups)
        return [n.decode() if isinstance(n, bytes) else str(n) for n in np.atleast_1d(laws)]

    def to_xarray(self, frames: Frames | None = None) -> Any:
        """The result as an :class:`xarray.Dataset` (needs xarray: ``pip install xarray``): every
        dataset it holds as a variable named by its path (``tentacles/position`` ->
        ``tentacles_position``), with named dimensions (``time``, ``tentacle``, ``particle``,
        ``xyz``, ``margin_point``, ``bell_particle``, ``vertex``, ``triangle``, ``corner``,
        ``spring``, ``end``, ``fluid_particle``, ``dimension``), ``time`` (s) as a coordinate,
        ``xyz`` labelled "x", "y", "z", and each variable's ``units`` and meaning as attributes.
        ``frames``: only those frames of the per-frame arrays (as :meth:`read`; all by
        default). Everything read is loaded into memory."""
        try:
            import xarray
        except ImportError:
            raise InputError(
                "Result.to_xarray needs xarray, which is not installed: pip install xarray"
            ) from None
        chosen = slice(None) if frames is None else frames
        if isinstance(chosen, numbers.Integral):  # one frame: keep its time axis
            chosen = [int(chosen)]
        variables = {}
        for field in fields.FIELDS:
            if field is fields.TIME or not self.has(field):
                continue
            data = self.read(field, chosen) if field.per_frame else self.read(field)
            dims = dimension_names(self._owner(field))
            described = {"units": field.units, "long_name": field.doc}
            variables[field.path.replace("/", "_")] = xarray.Variable(dims, data, described)
        time = self.read(fields.TIME, chosen)
        coords: dict[str, Any] = {
            "time": ("time", time, {"units": "s", "long_name": fields.TIME.doc})
        }
        if any("xyz" in v.dims for v in variables.values()):
            coords["xyz"] = ("xyz", np.array(["x", "y", "z"]))
        attrs: dict[str, Any] = {
            "scene": self.scene_text,
            "fps": float(self.file.attrs.get("fps", 0.0)),
            "tentacle_groups": ", ".join(self.tentacle_groups),
        }
        return xarray.Dataset(variables, coords=coords, attrs=attrs)

    def _owner(self, field: Field) -> Field:
        """The field whose dataset ``field``'s is: its own, or the one it is a hard link to
        (:data:`SHARED_DATASETS`)."""
        target = SHARED_DATASETS.get(field.path)
        if (
            target is not None
            and self.has(target)
            and self.file[field.path] == self.file[target.path]
        ):
            return target
        return field

    def group_number(self, group: str | int) -> int:
        """The index of ``group`` (its name, or its index) in :attr:`tentacle_groups`; raises
        :class:`InputError` naming the groups for one the result does not have."""
        names = self.tentacle_groups
        if isinstance(group, int | np.integer) and not isinstance(group, bool):
            if 0 <= group < len(names):
                return int(group)
        elif group in names:
            return names.index(str(group))
        listed = ", ".join(f"{k} '{name}'" for k, name in enumerate(names))
        raise InputError(f"{self.path}: no tentacle group {group!r}; its groups are {listed}")

    def group_tentacles(self, group: str | int) -> np.ndarray:
        """(Tg,) int64: the simulated tentacles (indices into the T axis) of ``group`` (a name
        or an index into :attr:`tentacle_groups`), in order."""
        return np.flatnonzero(self.tentacle_group == self.group_number(group))

    def group_positions(self, group: str | int, frames: Frames | None = None) -> np.ndarray:
        """(F, Tg, Pg, 3) float64, m: the particles of ``group``'s Tg tentacles, root first,
        trimmed to the group's own Pg particles (no NaN padding); ``frames`` as in
        :meth:`read` (an index drops the frame axis)."""
        return self._group_rows(fields.TENTACLE_POSITION, group, frames)

    def group_velocities(self, group: str | int, frames: Frames | None = None) -> np.ndarray:
        """(F, Tg, Pg, 3) float64, m/s: their velocities, as :meth:`group_positions`."""
        return self._group_rows(fields.TENTACLE_VELOCITY, group, frames)

    def _group_rows(self, field: Field, group: str | int, frames: Frames | None) -> np.ndarray:
        rows = self.group_tentacles(group)
        particles = int(self.tentacle_particles[rows].max()) if rows.size else 0
        return self.read(field, frames)[..., rows, :particles, :]

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
        """The frames the scene asks for (``round(duration * fps) + 1``); :attr:`frames` holds
        those written so far."""
        return int(self.file.attrs["frames_expected"])

    @property
    def complete(self) -> bool:
        """Whether every frame the scene asks for is written (a killed run's result is not)."""
        return self.frames == self.expected_frames

    @property
    def scene_text(self) -> str:
        """The resolved scene the run was made from, as TOML text (every key explicit)."""
        return str(self.file.attrs["scene"])

    @property
    def scene(self) -> Any:
        """The :class:`jellysim.Scene` the run was made from (:attr:`scene_text`, read under
        today's schema: keys added since take their defaults)."""
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
