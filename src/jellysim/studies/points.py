"""One sweep point run to its own folder, as a worker process or a Dask task runs it: a finished
point is kept, a killed one resumes from its checkpoint, anything else starts over.

A point's folder is ``SWEEP/points/<hash>``, the hash of its resolved scene (TOML text), so the
same scene is found again by any sweep writing to that folder. Workers report progress through a
small file in the point's folder (``progress``: the last frame done), which the sweep reads; that
works alike for local processes and for a cluster whose workers share the sweep's file system.
A worker whose run compiles the kernels says so likewise (``compiling``), so the sweep shows the
compile notice once, not once per worker.
"""

from __future__ import annotations

import fcntl
import hashlib
import logging
import os
import time
import tomllib
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from jellysim.config import load_scene
from jellysim.config.load import same_scene
from jellysim.errors import InputError, JellysimError
from jellysim.io.checkpoint import CHECKPOINT_FILE
from jellysim.io.result import RESULT_FILE, Result
from jellysim.simulation.run import COMPILE_NOTICE, run
from jellysim.studies.traces import format_value

POINTS_FOLDER = "points"
PROGRESS_FILE = "progress"
NOTICE_FILE = "compiling"  # there while a worker's run compiles the kernels (its notice)
RUN_LOG = logging.getLogger("jellysim.simulation.run")  # where a run logs the notice
REPORT_INTERVAL = 0.5  # s between a worker's progress reports (and Dask cancellation checks)


@dataclass(frozen=True)
class PointTask:
    """What a worker needs to run one point: the resolved scene as TOML text, the folder; whether
    the sweep is ``quiet`` (then the run says nothing, not even the compile notice); ``threads``
    for Numba (None: on a Dask worker its share of the worker's, see :func:`use_point_threads`;
    elsewhere, as they are)."""

    index: int
    scene_toml: str
    folder: str
    estimate_check: bool = True
    quiet: bool = True
    threads: int | None = None


@dataclass(frozen=True)
class PointOutcome:
    """How a point ended: ``mode`` "kept" (finished before), "resumed" or "started"; ``status``
    0, or the exit status of its error (2 input, 3 unstable, ...) with ``message``."""

    index: int
    mode: str
    status: int = 0
    message: str = ""


class _Abandoned(Exception):
    """The Dask task's client is gone (the sweep was killed): stop at this frame boundary."""


def point_folder(sweep_folder: Path, scene_toml: str) -> Path:
    """``SWEEP/points/<first 16 hex digits of the scene text's SHA-256>``."""
    digest = hashlib.sha256(scene_toml.encode("utf-8")).hexdigest()[:16]
    return sweep_folder / POINTS_FOLDER / digest


def finished(folder: Path, scene_toml: str) -> bool:
    """Whether ``folder`` holds a complete result of this scene."""
    if not (folder / RESULT_FILE).is_file():
        return False
    try:
        with Result(folder) as result:
            return result.complete and same_scene(result.scene_text, scene_toml)
    except (OSError, JellysimError):  # a damaged or foreign file: the point runs again
        return False


def frames_done(folder: Path) -> int:
    """The last frame a worker reported done in ``folder`` (0 when none)."""
    try:
        return int((folder / PROGRESS_FILE).read_text(encoding="ascii"))
    except (OSError, ValueError):
        return 0


def run_point(task: PointTask, on_frame: Callable[[int], None] | None = None) -> PointOutcome:
    """Run (or keep, or resume) one point; never raises (but for BaseExceptions: Ctrl-C): an
    error comes back in the outcome, an unforeseen one (a bug) with status 1, alike in the
    sweep's process and in a worker (an exception does not always survive the trip back from a
    process or a Dask worker). ``on_frame`` is told each frame done (in the sweep's own process,
    which then shows the run's own compile notice; a worker leaves it to the sweep)."""
    folder = Path(task.folder)
    try:
        if finished(folder, task.scene_toml):
            return PointOutcome(task.index, "kept")
        folder.mkdir(parents=True, exist_ok=True)
        _wait_for_writer(folder)  # a run of a killed sweep may still be stopping
        if finished(folder, task.scene_toml):
            return PointOutcome(task.index, "kept")
        use_point_threads(task.threads)
        scene = load_scene(tomllib.loads(task.scene_toml))
        observer = _Reporter(folder, on_frame)
        quiet = True if task.quiet else None  # None: no bar of its own, but the compile notice
        resumable = (folder / CHECKPOINT_FILE).is_file() and (folder / RESULT_FILE).is_file()
        with _notice_to_file(folder, on_frame is None and not task.quiet):
            if resumable:
                try:
                    run(
                        scene,
                        folder,
                        resume=True,
                        quiet=quiet,
                        observers=[observer],
                        estimate_check=task.estimate_check,
                    )
                    return PointOutcome(task.index, "resumed")
                except InputError:  # the checkpoint does not fit (another version): start over
                    pass
            run(
                scene,
                folder,
                force=True,
                quiet=quiet,
                observers=[observer],
                estimate_check=task.estimate_check,
            )
        return PointOutcome(task.index, "started")
    except _Abandoned:
        return PointOutcome(task.index, "abandoned", 1, "the sweep that asked for it is gone")
    except JellysimError as err:
        return PointOutcome(task.index, "failed", err.exit_status, str(err))
    except OSError as err:
        where = f"{err.filename}: " if err.filename else ""
        return PointOutcome(task.index, "failed", 4, f"{where}{err.strerror or err}")
    except Exception as err:  # a bug: one line, as the command line reports one
        if os.environ.get("JELLYSIM_DEBUG"):
            traceback.print_exc()  # on the worker's stderr (a Dask worker's log)
        return PointOutcome(
            task.index,
            "failed",
            1,
            f"internal error: {type(err).__name__}: {err} (set JELLYSIM_DEBUG=1 for the traceback)",
        )


def use_point_threads(threads: int | None) -> None:
    """Give Numba ``threads`` threads for this point's run (the setting is per thread, so it is
    made in the thread that runs the point). None: on a Dask worker, its threads (NUMBA_NUM_THREADS:
    the cores its process may use, unless set) shared among the tasks it runs at once (its
    ``nthreads``, which should be 1); elsewhere, left as it is."""
    import numba

    most = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]
    if threads is None:
        at_once = _dask_worker_threads()
        if at_once is None:
            return
        threads = most // at_once
    numba.set_num_threads(max(1, min(threads, most)))


def _dask_worker_threads() -> int | None:
    """The tasks the Dask worker running this code runs at once; None outside a Dask worker."""
    try:
        from distributed import get_worker

        return max(1, int(get_worker().state.nthreads))
    except (ImportError, ValueError, AttributeError):
        return None


class _NoticeFilter(logging.Filter):
    """Turns the run's compile notice into the point folder's :data:`NOTICE_FILE`."""

    def __init__(self, folder: Path) -> None:
        super().__init__()
        self.path = folder / NOTICE_FILE

    def filter(self, record: logging.LogRecord) -> bool:
        if record.getMessage() != COMPILE_NOTICE:
            return True
        try:
            self.path.touch()
        except OSError:  # only a notice
            pass
        return False


@contextmanager
def _notice_to_file(folder: Path, active: bool) -> Iterator[None]:
    """While the body runs (if ``active``: in a worker), the run's compile notice is not written
    to the worker's stderr but left as :data:`NOTICE_FILE` in ``folder`` for the sweep, which
    shows it once; the file goes at the end."""
    if not active:
        yield
        return
    notice = _NoticeFilter(folder)
    RUN_LOG.addFilter(notice)
    try:
        yield
    finally:
        RUN_LOG.removeFilter(notice)
        notice.path.unlink(missing_ok=True)


def compiling(folder: Path) -> bool:
    """Whether a worker's run in ``folder`` is compiling the kernels (it gave the notice)."""
    return (folder / NOTICE_FILE).is_file()


class _Reporter:
    """The run's observer: writes the frame done to the point's progress file (at most every
    :data:`REPORT_INTERVAL` s, and at the last frame), tells ``on_frame``, and on a Dask worker
    stops the run when its task was cancelled (its client, the sweep, was killed)."""

    def __init__(self, folder: Path, on_frame: Callable[[int], None] | None) -> None:
        self.path = folder / PROGRESS_FILE
        self.on_frame = on_frame
        self.last = 0.0

    def __call__(self, loop: Any) -> None:
        if self.on_frame is not None:
            self.on_frame(loop.frame)
        now = time.monotonic()
        if now - self.last < REPORT_INTERVAL and loop.frame < loop.scene.frame_count - 1:
            return
        self.last = now
        temporary = self.path.with_name(PROGRESS_FILE + ".tmp")
        temporary.write_text(str(loop.frame), encoding="ascii")
        os.replace(temporary, self.path)
        if _dask_task_cancelled():
            raise _Abandoned


def _dask_task_cancelled() -> bool:
    """Whether this code runs as a Dask task that its scheduler has since cancelled (what happens
    to the running tasks of a client that disconnects). Outside a Dask worker: False."""
    try:
        from distributed import get_worker
        from distributed.worker import thread_state

        worker = get_worker()
        task = worker.state.tasks.get(thread_state.key)
    except (ImportError, ValueError, AttributeError):
        return False
    return task is None or task.state == "cancelled"


def _wait_for_writer(folder: Path) -> None:
    """Block until no run holds ``folder``'s writer lock (:func:`jellysim.io.folders.writing_lock`,
    an flock on the folder): the point's run in a killed sweep may still be stopping."""
    descriptor = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX)
    finally:
        os.close(descriptor)  # releases it at once: the run takes it again


def describe_point(point: dict[str, Any]) -> str:
    """``key = value, ...`` for messages."""
    return ", ".join(f"{key} = {format_value(value)}" for key, value in point.items())
