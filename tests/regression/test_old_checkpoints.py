"""Checkpoints written before issue 23's re-layout resume bit for bit.

``old_checkpoints/`` holds the checkpoints that the code before the re-layout (commit 4a8694b)
wrote after frame 2 of the two scenes below (the run stopped by an observer at frame 3). The
loops' state arrays kept their names, so the new code writes the same arrays at that frame, and a
run resumed from the old checkpoint ends with the same result as one never stopped.

The scene text stored in a checkpoint is compared without what only draws the run (``[look]``
and the render-time ``tentacles.interpolation``): issue 25 gave the moon-jelly presets a new look,
which changes no state. The old state is resumed under today's scene text.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scenes
from scenes import one_table

import jellysim
from regression.compare import differences, read_all

OLD = Path(__file__).resolve().parent / "old_checkpoints"
CASES: dict[str, tuple[str | dict[str, Any], dict[str, object]]] = {
    "forced-tentacles": (
        "forced-tentacles",
        {"duration": 0.2, "tentacles.count": 2, "solver.checkpoint_every": 2},
    ),
    "moon-jelly": (  # the preset as it was: one [tentacles] table, no oral arms
        one_table("moon-jelly"),
        {
            **scenes.SMALL_MOON,
            "duration": 0.4,
            "fps": 10.0,
            "tentacles.count": 2,
            "solver.checkpoint_every": 2,
        },
    ),
}


DRAWING_ONLY = {"look": None, "tentacles": "interpolation"}  # table -> key (None: the table)


def physics(scene_text: str) -> dict[str, object]:
    """A scene's TOML without the tables and keys that only change the pictures."""
    tables = tomllib.loads(scene_text)
    for table, key in DRAWING_ONLY.items():
        if key is None:
            tables.pop(table, None)
        elif isinstance(tables.get(table), dict):
            tables[table].pop(key, None)
    return tables


class _Stop(Exception):
    pass


def _stop_at_frame_3(simulation: jellysim.Simulation) -> None:
    if simulation.frame == 3:
        raise _Stop


@pytest.mark.parametrize("name", list(CASES))
def test_an_old_checkpoint_resumes_bit_for_bit(name: str, tmp_path: Path) -> None:
    preset, overrides = CASES[name]
    scene = jellysim.load_scene(preset, overrides)
    jellysim.run(scene, tmp_path / "whole").close()

    stopped = tmp_path / "stopped"
    with pytest.raises(_Stop):
        jellysim.run(scene, stopped, observers=[_stop_at_frame_3])
    checkpoint = stopped / "checkpoint.npz"
    with np.load(checkpoint) as new, np.load(OLD / f"{name}.npz") as old:
        assert sorted(new.files) == sorted(old.files)  # the same layout
        written = {key: new[key] for key in new.files if key != "scene"}
        stored = {key: old[key] for key in old.files if key != "scene"}
        assert physics(str(old["scene"])) == physics(str(new["scene"]))  # the same physics
        today = new["scene"].copy()
    assert differences(stored, written) == []  # and the same state, bit for bit
    np.savez(checkpoint, **stored, scene=today)  # resume from the old state
    jellysim.run(scene, stopped, resume=True).close()
    whole = read_all(tmp_path / "whole" / "result.h5")
    assert differences(whole, read_all(stopped / "result.h5")) == []
