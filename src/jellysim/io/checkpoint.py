"""Checkpoints: the full simulation state after a frame, written atomically (tmp + rename).

The state is everything the frame loop reads, so a resumed run continues bitwise identically:
tentacle positions and velocities and the frame index. The flow noise is a pure function of the
seed and the time (:mod:`jellysim.tentacle.flow`), so it needs no saved generator state.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from jellysim.config.load import same_scene
from jellysim.errors import InputError

CHECKPOINT_FILE = "checkpoint.npz"


def save_checkpoint(
    folder: Path, frame: int, scene_toml: str, state: dict[str, np.ndarray]
) -> None:
    """Write the state after ``frame`` (0-based index of the last frame written)."""
    path = folder / CHECKPOINT_FILE
    temporary = folder / (CHECKPOINT_FILE + ".tmp")
    with open(temporary, "wb") as handle:
        arrays: dict[str, Any] = {"frame": np.int64(frame), "scene": np.array(scene_toml), **state}
        np.savez(handle, **arrays)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(temporary, path)


def load_checkpoint(folder: Path, scene_toml: str) -> tuple[int, dict[str, np.ndarray]]:
    """The last checkpoint of the run in ``folder``; it must belong to the same scene."""
    path = folder / CHECKPOINT_FILE
    if not path.is_file():
        raise InputError(
            f"cannot resume '{folder}': the run stopped before its first checkpoint "
            "(start it again with --force)"
        )
    try:
        with np.load(path) as data:
            saved_scene = str(data["scene"])
            frame = int(data["frame"])
            state = {k: data[k].copy() for k in data.files if k not in ("frame", "scene")}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as err:
        # truncated, empty, bit-flipped or not a checkpoint at all
        detail = f"{type(err).__name__}: {err}" if str(err) else type(err).__name__
        raise InputError(
            f"cannot resume '{folder}': {path.name} is damaged ({detail}); "
            "run with --force to start again"
        ) from None
    if not same_scene(saved_scene, scene_toml):
        raise scene_mismatch(folder)
    return frame, state


def scene_mismatch(folder: Path) -> InputError:
    """The error for resuming ``folder`` with a scene other than the one it was run with."""
    return InputError(
        f"cannot resume '{folder}': the scene differs from the run being resumed "
        "(compare with its scene.toml, or run with --force to start again)"
    )


def remove_checkpoint(folder: Path) -> None:
    (folder / CHECKPOINT_FILE).unlink(missing_ok=True)
