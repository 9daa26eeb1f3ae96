"""A scene run to ``result.h5``: the result store, checkpoints, resume and progress around any
frame loop (:class:`jellysim.simulation.loop.FrameLoop`)."""

from __future__ import annotations

import logging
import os
import signal
import threading
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from numba.core import event

from jellysim.config import Scene, load_scene, scene_to_toml
from jellysim.config.load import same_scene
from jellysim.errors import InputError, OutputError, RunInterrupted
from jellysim.io.checkpoint import (
    CHECKPOINT_FILE,
    load_checkpoint,
    remove_checkpoint,
    save_checkpoint,
    scene_mismatch,
)
from jellysim.io.folders import check_writable, output_folder, writing_lock
from jellysim.io.result import RESULT_FILE, Result, read_frames
from jellysim.io.xdmf import write_xdmf
from jellysim.progress import progress
from jellysim.simulation.estimate import check_costs
from jellysim.simulation.loop import FrameLoop, Observer, Simulation, make_loop

log = logging.getLogger(__name__)

SCENE_FILE = "scene.toml"
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)

# A first run on a machine compiles the kernels (10 to 60 s); later runs load them from Numba's
# cache in well under a second. When Numba starts compiling one (its "numba:compile" event, which
# a cache hit does not raise), one line says so instead of silence (docs/decisions.md, "A notice
# while kernels compile").
COMPILE_NOTICE = (
    "compiling jellysim's kernels for this machine (a first run only: up to a minute; later "
    "runs load them from Numba's cache)"
)


# fluid.device = "cuda" moves the MPS water (and a soft bell's springs in it) to the GPU; the
# tentacles and an animated bell always step on the CPU. A scene without MPS water therefore
# has nothing to put on the GPU: it runs as on the CPU, and one line says so rather than let
# `--device cuda` look as if it had been obeyed (docs/decisions.md, "--device cuda without
# water").
DEVICE_NOTICE = (
    "{name}: fluid.device = 'cuda' has nothing to run on the GPU: the scene has no MPS water "
    "(fluid.model = '{model}'; only the water and a soft bell in it step on the GPU), so its "
    "tentacles and bell step on the CPU"
)


def device_notice(scene: Scene) -> str | None:
    """:data:`DEVICE_NOTICE` for ``scene`` where it asks for the GPU but has no MPS water,
    else None."""
    if scene.fluid.device == "cuda" and scene.fluid.model != "mps":
        return DEVICE_NOTICE.format(name=scene.name, model=scene.fluid.model)
    return None


def default_out(scene: Scene) -> Path:
    return Path("out") / scene.name


class _CompileNotice(event.Listener):
    """Logs :data:`COMPILE_NOTICE` as a warning (seen on stderr with no logging set up) when
    Numba starts its first compilation while installed."""

    def __init__(self) -> None:
        self.said = False

    def on_start(self, what: event.Event) -> None:
        if not self.said:
            self.said = True
            log.warning(COMPILE_NOTICE)

    def on_end(self, what: event.Event) -> None:
        pass


@contextmanager
def _compile_notice(show: bool) -> Iterator[None]:
    """While the body runs, say once that kernels compile if Numba compiles any, if ``show``."""
    if not show:
        yield
        return
    with event.install_listener("numba:compile", _CompileNotice()):
        yield


def _write_text_atomic(path: Path, text: str) -> None:
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(text, encoding="utf-8")
    os.replace(temporary, path)


def _check_state(folder: Path, loop: FrameLoop, state: dict[str, np.ndarray]) -> None:
    """A checkpoint must hold every array of the loop's state, each of its shape."""
    for name, array in loop.checkpoint_state().items():
        saved = state.get(name)
        if saved is None or saved.shape != array.shape:
            raise InputError(
                f"cannot resume '{folder}': {CHECKPOINT_FILE} does not hold this scene's state "
                f"('{name}' {'is missing' if saved is None else f'has shape {saved.shape}'}); "
                "run with --force to start again"
            )


def run(
    scene: Scene | str | os.PathLike[str] | Mapping[str, Any],
    out: str | os.PathLike[str] | None = None,
    *,
    overrides: Mapping[str, Any] | None = None,
    force: bool = False,
    resume: bool = False,
    quiet: bool | None = None,
    observers: list[Observer] | None = None,
    estimate_check: bool = True,
) -> Result:
    """Run a scene to ``out/result.h5`` (default ``out/<name>``) and return the open result.

    ``force`` replaces an existing result; ``resume`` continues it from its last checkpoint.
    ``quiet=False`` shows a progress bar with ETA on runs longer than two seconds and the
    estimate's line when the run is long; by default (None) neither shows, but a first run that
    compiles the kernels says so in one line on stderr (a logging warning); ``quiet=True`` says
    nothing.
    Before anything is allocated the run's memory, disk and time are estimated
    (:mod:`jellysim.simulation.estimate`): beyond the machine's memory or the folder's free
    space it is refused (InputError) unless ``estimate_check`` is False.
    """
    if not isinstance(scene, Scene) or overrides:
        scene = load_scene(scene if not isinstance(scene, os.PathLike) else str(scene), overrides)
    folder = Path(out) if out is not None else default_out(scene)
    result_path = folder / RESULT_FILE
    scene_toml = scene_to_toml(scene)
    if force and resume:
        raise InputError("--force and --resume exclude each other")
    if folder.exists() and not folder.is_dir():
        raise InputError(f"--out {folder}: exists and is not a folder")
    if result_path.exists() and not (force or resume):
        raise InputError(f"{result_path} exists; --force replaces it, --resume continues it")
    if resume and not result_path.exists():
        raise InputError(f"nothing to resume in '{folder}': no {RESULT_FILE}")

    check_writable(folder)
    notice = device_notice(scene)
    if notice is not None and quiet is not True:
        log.warning(notice)
    replaced = result_path.stat().st_size if result_path.is_file() else 0  # or continued
    check_costs(scene, folder, reclaimed=replaced, quiet=quiet is not False, enforce=estimate_check)
    # From here a stop signal ends the run at the next frame boundary (setting up included).
    with _stop_signals() as stop:
        loop = make_loop(scene)
        loop.observers.extend(observers or [])
        if not resume:
            output_folder(folder)
        with writing_lock(folder):
            return _run(loop, scene, folder, scene_toml, resume, quiet, stop)


@contextmanager
def _stop_signals() -> Iterator[list[int]]:
    """While the block runs, SIGINT and SIGTERM are recorded (the list gets the signal's number)
    instead of raised inside a compiled kernel, so the run stops at the next frame boundary.
    Outside the main thread, where Python cannot take signals, nothing changes."""
    received: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return

    def record(number: int, _frame: object) -> None:
        received.append(number)

    previous = {number: signal.signal(number, record) for number in STOP_SIGNALS}
    try:
        yield received
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def _checkpoint(folder: Path, loop: FrameLoop, scene_toml: str, written: int) -> None:
    """Save the state after the loop's frame; an output that refuses it is an OutputError (the
    previous checkpoint, written atomically, stays)."""
    try:
        save_checkpoint(folder, loop.frame, scene_toml, loop.checkpoint_state())
    except OSError as err:
        (folder / (CHECKPOINT_FILE + ".tmp")).unlink(missing_ok=True)
        raise OutputError(
            f"{folder}: cannot write {CHECKPOINT_FILE} ({err.strerror or err}); frames "
            f"0-{written - 1} are written in {RESULT_FILE}",
            frames=written,
        ) from None


def _way_on(folder: Path) -> str:
    """How to continue a run the output stopped: from its checkpoint, or again from the start."""
    try:
        resumable = (folder / CHECKPOINT_FILE).is_file()
    except OSError:
        resumable = False
    if resumable:
        return (
            f"; once that is mended, continue with "
            f"'jellysim run {_scene_argument(folder)} --out {folder} --resume'"
        )
    return "; once that is mended, run the scene again with --force"


def _scene_argument(folder: Path) -> str:
    """What to name the scene on a resume's command line: the run's resolved scene file."""
    return str(folder / SCENE_FILE)


def _run(
    loop: Simulation,
    scene: Scene,
    folder: Path,
    scene_toml: str,
    resume: bool,
    quiet: bool | None,
    stop: list[int],
) -> Result:
    """The run itself, the folder's writer lock held."""
    result_path = folder / RESULT_FILE
    if resume:
        with Result(folder) as existing:
            same = same_scene(existing.scene_text, scene_toml)
            complete = existing.complete
            written = existing.frames
            if same and complete:
                # A run killed after its last frame but before its closing sidecar write left
                # a sidecar of fewer frames (the writer skips rewrites closer together than
                # SIDECAR_PAUSE): the sidecar is written again, listing every frame, from the
                # file as Result opened it (an older jellysim's SWMR-flagged file too). A
                # sidecar that already lists them is left as it is, bytes and time.
                write_xdmf(
                    existing.file,
                    result_path,
                    result_path.with_suffix(".xdmf"),
                    range(written),
                    only_if_changed=True,
                )
        if not same:
            raise scene_mismatch(folder)
        if complete:
            log.info("%s is complete; nothing to resume", result_path)
            return Result(folder)
        frame, state = load_checkpoint(folder, scene_toml)
        if not 0 <= frame < min(written, scene.frame_count - 1):
            raise InputError(
                f"cannot resume '{folder}': {CHECKPOINT_FILE} is of frame {frame}, but "
                f"{RESULT_FILE} holds frames 0-{written - 1} of {scene.frame_count}; "
                "run with --force to start again"
            )
        _check_state(folder, loop, state)
        loop.restore(frame, state)
        kept = read_frames(result_path, loop.datasets(), frame + 1)
        writer = loop.writer(result_path, scene_toml, kept)
    else:
        output_folder(folder)
        remove_checkpoint(folder)
        try:
            _write_text_atomic(folder / SCENE_FILE, scene_toml)
        except OSError as err:
            raise OutputError(
                f"{folder}: cannot write {SCENE_FILE} ({err.strerror or err}); nothing is run",
                frames=0,
            ) from None
        writer = loop.writer(result_path, scene_toml)
        writer.append(loop.frame_values())

    log.info("%s: %s, %d frames -> %s", scene.name, loop.describe(), scene.frame_count, result_path)
    every = scene.solver.checkpoint_every
    try:
        start = time.perf_counter()
        with _compile_notice(show=quiet is not True):
            loop.prepare()
        log.info("compiled kernels ready in %.1f s", time.perf_counter() - start)
        total, done = scene.frame_count - 1, loop.frame
        with progress(total, done, quiet is not False, "simulating", delay=2.0) as bar:
            while loop.frame < scene.frame_count - 1:
                loop.step_frame()
                writer.append(loop.frame_values())
                last = loop.frame == scene.frame_count - 1
                if (loop.frame % every == 0 or stop) and not last:
                    writer.flush()  # the checkpoint's frame must be on disk first
                    _checkpoint(folder, loop, scene_toml, writer.frames)
                bar.update(1)
                if stop and not last:
                    raise RunInterrupted(
                        f"{signal.Signals(stop[0]).name} at t = {loop.time:.6g} s: frames "
                        f"0-{loop.frame} are written, with a checkpoint; continue with "
                        f"'jellysim run {_scene_argument(folder)} --out {folder} --resume'",
                        signal_number=stop[0],
                        frame=loop.frame,
                    )
        writer.flush()
    except OutputError as err:
        writer.close(discard=True)
        raise OutputError(f"{err}{_way_on(folder)}", frames=err.frames) from None
    finally:
        writer.close()
    loop.finish()
    remove_checkpoint(folder)
    return Result(folder)
