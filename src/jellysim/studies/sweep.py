"""A sweep: one run per point, spread over local processes (the default) or the workers of a
Dask cluster, each point in its own folder under the sweep's (so a killed sweep resumes), with
one progress bar across the points (frames done of all frames)."""

from __future__ import annotations

import concurrent.futures as cf
import ctypes
import logging
import multiprocessing
import os
import signal
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from jellysim import fields
from jellysim.config import Scene, load_scene, scene_to_toml
from jellysim.config.load import parse_override
from jellysim.errors import InputError, JellysimError
from jellysim.io.folders import check_writable, output_folder
from jellysim.io.result import Result
from jellysim.progress import progress
from jellysim.simulation.run import COMPILE_NOTICE
from jellysim.studies.plan import Plan, grid, listed
from jellysim.studies.points import (
    NOTICE_FILE,
    PointOutcome,
    PointTask,
    compiling,
    describe_point,
    finished,
    frames_done,
    point_folder,
    run_point,
)
from jellysim.studies.traces import Trace, own_particles

log = logging.getLogger(__name__)

POLL_INTERVAL = 0.5  # s between looks at the points' progress files


class SweepFailed(JellysimError):
    """A point of the sweep failed; ``exit_status`` is that of its error (2 input, 3 unstable,
    4 output, 128 + a signal's number when a signal stopped its worker, 1 otherwise: its
    worker died, or an internal error)."""

    def __init__(self, message: str, exit_status: int) -> None:
        super().__init__(message)
        self.exit_status = exit_status


@dataclass(frozen=True)
class SweepRun:
    """A finished sweep: its ``folder``, ``plan``, one trace per point (in the plan's order),
    each point's run folder relative to ``folder``, and how many points were ``kept`` (finished
    before), ``resumed`` and ``started``."""

    folder: Path
    plan: Plan
    traces: list[Trace]
    point_folders: list[str]
    kept: int
    resumed: int
    started: int


def sweep(
    scene: str | Path | Mapping[str, Any],
    key: str | Mapping[str, Sequence[Any]] | Sequence[Mapping[str, Any]],
    values: Sequence[Any] | None = None,
    overrides: Mapping[str, Any] | Sequence[str] | None = None,
    tentacle: int = 0,
    *,
    paired: bool = False,
    out: str | os.PathLike[str] | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    quiet: bool = True,
) -> list[Trace]:
    """Run ``scene`` once per point; the traces of ``tentacle``'s root and tip, one per point.

    The points: ``key`` and ``values`` (one key), or ``key`` a mapping of keys to their values
    (every combination, the first key varying slowest; ``paired=True`` pairs the lists in order
    instead), or ``key`` a list of points (mappings of the same keys to values).
    ``overrides`` apply to every point. ``tentacle`` numbers the simulated tentacles across every
    group, in the scene's order (the result's T axis: ``tentacles/group`` tells its group); its
    tip is its own last particle.

    Each point runs to ``out/points/<hash of its scene>`` (a temporary folder, removed after,
    when ``out`` is None), so a sweep run again with the same ``out`` keeps its finished points
    and resumes a killed one from its checkpoint. Points run at once in ``workers`` local
    processes (default: one per core), or on the Dask cluster whose scheduler is at
    ``scheduler`` (``out`` then names a folder its workers share)."""
    plan = _plan(key, values, paired)
    return run_sweep(scene, plan, overrides, tentacle, out, workers, scheduler, quiet).traces


def _plan(
    key: str | Mapping[str, Sequence[Any]] | Sequence[Mapping[str, Any]],
    values: Sequence[Any] | None,
    paired: bool,
) -> Plan:
    if isinstance(key, str):
        if values is None:
            raise InputError(f"sweep {key!r}: give its values")
        return grid({key: values})
    if values is not None:
        raise InputError("values go with a single key; give a mapping of keys to values instead")
    if isinstance(key, Mapping):
        return grid(key, paired)
    return listed(key)


def run_sweep(
    scene: str | Path | Mapping[str, Any],
    plan: Plan,
    overrides: Mapping[str, Any] | Sequence[str] | None,
    tentacle: int,
    out: str | os.PathLike[str] | None,
    workers: int | None = None,
    scheduler: str | None = None,
    quiet: bool = True,
    estimate_check: bool = True,
) -> SweepRun:
    """The sweep itself: every point's scene is loaded and checked before anything runs or is
    written (a bad key or value is an InputError naming it)."""
    if workers is not None and workers < 1:
        raise InputError(f"--workers {workers}: expected at least 1")
    if workers is not None and scheduler is not None:
        raise InputError("--workers and --scheduler exclude each other: the cluster's workers run")
    if scheduler is not None and out is None:
        raise InputError("a sweep on a Dask cluster needs out=: a folder its workers share")
    base: dict[str, Any] = (
        dict(overrides)
        if isinstance(overrides, Mapping)
        else dict(parse_override(item) for item in overrides or [])
    )
    scenes = [load_scene(scene, {**base, **point}) for point in plan.points]
    particles = [_traced_particles(loaded, tentacle) for loaded in scenes]
    texts = [scene_to_toml(loaded) for loaded in scenes]
    _refuse_duplicates(plan, texts)
    with ExitStack() as stack:
        # The cluster first: an unreachable scheduler is refused before anything is written.
        cluster = _dask_executor(scheduler, stack) if scheduler is not None else None
        if out is None:
            folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="jellysim-")))
        else:
            folder = Path(out).absolute()
            check_writable(folder)
            output_folder(folder)
        folders = [point_folder(folder, text) for text in texts]
        outcomes = _run_points(
            scenes, texts, folders, workers, cluster, quiet, estimate_check, stack
        )
        failed = [o for o in outcomes.values() if o.status]
        if failed:
            first = min(failed, key=lambda o: o.index)
            others = f" ({len(failed)} points failed)" if len(failed) > 1 else ""
            raise SweepFailed(
                f"point {first.index} ({describe_point(plan.points[first.index])}): "
                f"{first.message}{others}; the finished points are kept: run the sweep again "
                "to continue",
                first.status,
            )
        traces = [
            _trace(where, point, tentacle, count)
            for where, point, count in zip(folders, plan.points, particles, strict=True)
        ]
    modes = [outcome.mode for outcome in outcomes.values()]
    return SweepRun(
        Path(out) if out is not None else folder,
        plan,
        traces,
        [str(where.relative_to(folder)) for where in folders],
        kept=modes.count("kept"),
        resumed=modes.count("resumed"),
        started=modes.count("started"),
    )


def _refuse_duplicates(plan: Plan, texts: list[str]) -> None:
    """Each point once: two points of one resolved scene (``--values 0,0``, or ``1`` and
    ``1.0``) would be one run counted and tabled twice."""
    first: dict[str, int] = {}
    for index, text in enumerate(texts):
        if text in first:
            raise InputError(
                f"points {first[text]} ({describe_point(plan.points[first[text]])}) and {index} "
                f"({describe_point(plan.points[index])}) are the same scene: give each point once"
            )
        first[text] = index


def _traced_particles(scene: Scene, tentacle: int) -> int:
    if scene.tentacle_count == 0:
        raise InputError(
            f"{scene.name} has no tentacles (tentacles.count = 0): a sweep traces a "
            "tentacle's root and tip; set tentacles.count"
        )
    return own_particles(scene, tentacle)


def _trace(folder: Path, point: dict[str, Any], tentacle: int, particles: int) -> Trace:
    """The root's and the tip's x of ``tentacle`` (its own last particle, ``particles`` - 1: the
    rows beyond are NaN padding) from a point's result."""
    with Result(folder) as result:
        x = result.dataset(fields.TENTACLE_POSITION)[:, tentacle, :, 0]
        time = result.time
    value = next(iter(point.values())) if len(point) == 1 else tuple(point.values())
    return Trace(value, time, x[:, 0].copy(), x[:, particles - 1].copy(), dict(point))


def _run_points(
    scenes: list[Scene],
    texts: list[str],
    folders: list[Path],
    workers: int | None,
    cluster: cf.Executor | None,
    quiet: bool,
    estimate_check: bool,
    stack: ExitStack,
) -> dict[Path, PointOutcome]:
    """Run each point (each its own folder: :func:`_refuse_duplicates`) in this process, in
    local worker processes or on the ``cluster``; the outcome of each folder."""
    tasks: dict[Path, PointTask] = {}
    frames: dict[Path, int] = {}
    for index, (loaded, text, where) in enumerate(zip(scenes, texts, folders, strict=True)):
        tasks[where] = PointTask(index, text, str(where), estimate_check, quiet)
        frames[where] = loaded.frame_count - 1
    outcomes = {
        where: PointOutcome(task.index, "kept")
        for where, task in tasks.items()
        if finished(where, task.scene_toml)
    }
    at_once = min(workers or _cores(), len(tasks) - len(outcomes))
    # Numba's threads: a local worker's share of the cores; on a cluster, its worker's share
    # (use_point_threads); one point after another in this process: as they are.
    threads = max(1, _cores() // at_once) if cluster is None and at_once > 1 else None
    pending = [
        replace(task, threads=threads) for where, task in tasks.items() if where not in outcomes
    ]
    total = sum(frames.values())
    seen = {where: frames[where] if where in outcomes else frames_done(where) for where in frames}
    bar = stack.enter_context(progress(total, sum(seen.values()), quiet, "sweep", delay=2.0))
    shown = sum(seen.values())

    def report() -> None:
        nonlocal shown
        now = sum(seen.values())
        if now > shown:
            bar.update(now - shown)
            shown = now

    if not pending:
        return outcomes
    if cluster is None and at_once == 1:
        for task in pending:  # one at a time in this process: no process to start
            where = Path(task.folder)

            def on_frame(frame: int, where: Path = where) -> None:
                seen[where] = max(seen[where], frame)
                report()

            outcomes[where] = run_point(task, on_frame)
            if not outcomes[where].status:
                seen[where] = frames[where]
            report()
        return outcomes
    executor = cluster or _process_executor(at_once, stack)
    for task in pending:  # a notice left by a killed sweep's worker
        (Path(task.folder) / NOTICE_FILE).unlink(missing_ok=True)
    futures = {executor.submit(run_point, task): Path(task.folder) for task in pending}
    waiting = set(futures)
    noticed = quiet  # the workers' compile notice, shown once for the sweep
    while waiting:
        done, waiting = cf.wait(waiting, timeout=POLL_INTERVAL, return_when=cf.FIRST_COMPLETED)
        for future in done:
            where = futures[future]
            outcomes[where] = _outcome(future, tasks[where].index)
            if not outcomes[where].status:
                seen[where] = frames[where]
        for future in waiting:
            where = futures[future]
            seen[where] = max(seen[where], min(frames_done(where), frames[where]))
            if not noticed and compiling(where):
                noticed = True
                _show_notice()
        report()
    return outcomes


def _show_notice() -> None:
    """The compile notice, once for the sweep (each worker compiles; each would say so), as a
    run gives it (a logging warning), clear of the progress bar."""
    from tqdm import tqdm

    with tqdm.external_write_mode():
        log.warning(COMPILE_NOTICE)


def _outcome(future: cf.Future[PointOutcome], index: int) -> PointOutcome:
    """The point's outcome, or a failure when its worker died (killed, out of memory)."""
    try:
        return future.result()
    except Exception as err:  # the pool or the cluster lost the worker running it
        return PointOutcome(index, "failed", 1, f"its worker died ({type(err).__name__}: {err})")


def _cores() -> int:
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def _process_executor(workers: int, stack: ExitStack) -> cf.Executor:
    """``workers`` fresh Python processes (spawned: no inherited threads or kernels); they end
    with this process (each point's task gives Numba its share of the cores)."""
    executor = cf.ProcessPoolExecutor(
        workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_start_worker,
        initargs=(os.getpid(),),
    )
    stack.enter_context(_shut_down(executor))
    return executor


@contextmanager
def _shut_down(executor: cf.Executor) -> Iterator[None]:
    """Wait for the workers at the end; on an exception (Ctrl-C) drop the points not started
    (the running ones got the signal too, or their parent's death: they stop at a frame with a
    checkpoint)."""
    try:
        yield
    except BaseException:
        executor.shutdown(wait=True, cancel_futures=True)
        raise
    executor.shutdown(wait=True)


def _start_worker(parent: int) -> None:
    """A local worker: SIGTERM when the sweep's process dies, whatever kills it (Linux), so its
    run stops at a frame with a checkpoint instead of running on unseen."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: a killed sweep's workers finish their point
        pass
    if os.getppid() != parent:  # the sweep died before the signal was asked for
        os._exit(1)


def _dask_executor(scheduler: str, stack: ExitStack) -> cf.Executor:
    """An executor on the Dask cluster whose scheduler is at the address ``scheduler``, or is
    described by the scheduler file of that name (``dask scheduler --scheduler-file``,
    dask-jobqueue); an unreachable one is an InputError."""
    try:
        import distributed
        from distributed.comm.addressing import parse_address, parse_host_port
    except ImportError:
        raise InputError(
            "--scheduler needs dask.distributed, which is not installed: "
            "pip install 'jellysim[dask]'"
        ) from None
    where: dict[str, str] = {}
    if Path(scheduler).is_file():
        where["scheduler_file"] = scheduler
    else:
        try:  # checked first: a Client given a malformed address fails noisily as it is freed
            scheme, location = parse_address(scheduler)
            if scheme in ("tcp", "tls"):
                parse_host_port(location)
        except ValueError as err:
            raise InputError(
                f"--scheduler {scheduler}: not a scheduler address ({err}); expected e.g. "
                "tcp://10.0.0.5:8786, or a scheduler file"
            ) from None
        where["address"] = scheduler
    try:
        client = distributed.Client(**where, set_as_default=False)  # type: ignore[arg-type]
    except (OSError, TimeoutError, ValueError) as err:
        reason = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise InputError(
            f"--scheduler {scheduler}: cannot reach a Dask scheduler ({reason})"
        ) from None
    stack.callback(client.close)
    return client.get_executor(pure=False)
