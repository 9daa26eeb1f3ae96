"""Checkpoints written before issue 23's re-layout still resume.

``old_checkpoints/`` holds the checkpoints that the code before the re-layout (commit 4a8694b)
wrote after frame 2 of the two scenes below (the run stopped by an observer at frame 3), on the
tests' pinned floating-point path (``tests/pinning.py``; written again on it from that commit in a
worktree when the pin came, the scene texts unchanged). The loops' state arrays kept their
names, so the new code writes the same arrays at that frame, and a run resumed from the old
checkpoint ends with the result of one never stopped.

Bit for bit, but for three things the checkpoints' code did differently:

- The tentacles' state. Issue 25's faster banded solve of the tentacle step (docs/decisions.md)
  sums in another order than the code that wrote these checkpoints, so the tentacle positions
  and velocities differ from theirs in the last bits (relative to the largest value, under 1e-12
  in these runs). For those arrays, in the checkpoint and in every frame of the resumed result,
  the test asks for agreement within ``ROUND_OFF`` of the array's largest value, and of their
  constraint error (a round-off figure itself) that it stays within the projection's tolerance.
- The checkpoint's ``scene`` text, which records every key of the scene: issue 25 changed
  moon-jelly's look (colours, transparency, gonads), and a run refuses to resume from a
  checkpoint whose text differs from its scene's. So the text is compared without what only
  draws the run (``[look]`` and the render-time ``tentacles.interpolation``), and the run
  resumes from the old checkpoint's state (its frame and arrays, as stored) under the present
  scene text. Issue 25 also gave the moon-jelly presets oral arms: this test runs moon-jelly as
  it was, its tentacles as one table (``scenes.one_table``).

- The water's sums (moon-jelly). Since 2026-11-28 the fluid kernels sum in the order they are
  written, where the checkpoints' code let LLVM reorder the sums for the vector width
  (docs/decisions.md, "Sums in the written order"). The water, and the bell and tentacles it
  moves, then differ from the checkpoint's in the last bits (relative to the largest value,
  over 1e-12 and under 1e-10 in this run): with water, every floating-point array is compared
  within ``ROUND_OFF`` of its largest value.

Everything else (the layout, the frame, the integer and boolean arrays, and without water the
bell's state and the other datasets) must still be identical. A checkpoint written by the
present code resumes bit for bit (tests/integration/test_resume.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scenes
from pinning import NOT_PINNED, PINNED
from scenes import one_table

import jellysim
from jellysim.config.load import recorded_tree, scene_from_tree
from jellysim.config.schema import Scene
from jellysim.io.checkpoint import save_checkpoint
from jellysim.tentacle.kernels import PROJECTION_TOLERANCE
from regression.compare import differences, read_all

OLD = Path(__file__).resolve().parent / "old_checkpoints"
CASES: dict[str, tuple[str | dict[str, Any], dict[str, object]]] = {
    "forced-tentacles": (
        "forced-tentacles",
        {"duration": 0.2, "tentacles.count": 2, "solver.checkpoint_every": 2},
    ),
    "moon-jelly": (  # the preset as it was: one [tentacles] table, no oral arms, the paper's flow
        one_table("moon-jelly"),
        {
            **scenes.SMALL_MOON,
            "flow.model": "bell",
            "bell.spring_stiffness": 20.0,  # the paper's k, the preset's until issue 26
            "bell.muscle_band": 0.3,  # the paper's uniform muscle band, until issue 26
            "bell.muscle_taper": 0.0,
            "bell.root_placement": "particles",  # the roots at the particles, until issue 25
            "bell.arm_anchor": "margin",  # the arms on the margin plane, until issue 25
            "bell.tentacle_contact": False,  # nothing kept the tentacles out, until issues 25-26
            "fluid.neighbour_skin": 0.0,  # searched twice a step, until 2026-11-29
            "duration": 0.4,
            "fps": 10.0,
            "tentacles.count": 2,
            "solver.checkpoint_every": 2,
        },
    ),
}


DRAWING_ONLY = {"look": None, "tentacles": "interpolation"}  # table -> key (None: the table)


def physics(scene_text: str) -> Scene:
    """A scene's TOML without the tables and keys that only change the pictures, as the scene it
    describes under today's schema (keys added since at their defaults; a missing
    ``flow.model`` as "bell", what the run that wrote the text had: ``recorded_tree``)."""
    tables = recorded_tree(scene_text)
    for table, key in DRAWING_ONLY.items():
        if key is None:
            tables.pop(table, None)
        elif isinstance(tables.get(table), dict):
            tables[table].pop(key, None)
    return scene_from_tree(tables)


# What the solve's new summation order changes in positions and velocities, relative to the
# array's largest value (the reference runs of 0.1 s: up to 2e-10, in velocities).
ROUND_OFF = 1e-9


def _kind(key: str, value: np.ndarray, water: bool) -> str:
    """``state`` for the tentacles' positions and velocities (checkpoint arrays and result
    datasets) and, in a run with ``water``, for every floating-point array; ``error`` for the
    tentacles' constraint error, ``other`` for the rest."""
    name = key.rsplit("/", 1)[-1].removeprefix("tentacles_")
    tentacles = key.startswith("data:tentacles/") or ":" not in key
    if key == "data:tentacles/constraint_error":
        return "error"
    if key == "scene":
        return "scene"
    if tentacles and name in ("position", "positions", "velocity", "velocities"):
        return "state"
    if water and value.dtype.kind == "f":
        return "state"
    return "other"


def _assert_same_but_round_off(
    expected: dict[str, np.ndarray], actual: dict[str, np.ndarray]
) -> None:
    """Bit for bit, except the tentacles' state and, with water, every floating-point array
    (within ``ROUND_OFF``), the tentacles' constraint error (a round-off figure itself: within
    the projection's tolerance in both) and the scene text (not compared)."""
    water = any("fluid" in key for key in expected)
    kinds = {key: _kind(key, expected[key], water) for key in expected}
    assert "state" in kinds.values()
    others = [k for k, kind in kinds.items() if kind == "other"]
    assert (
        differences({k: expected[k] for k in others}, {k: actual[k] for k in others if k in actual})
        == []
    )
    assert expected.keys() == actual.keys()
    for key, kind in kinds.items():
        if kind == "scene":
            continue
        a, b = expected[key], actual[key]
        assert (a.dtype, a.shape) == (b.dtype, b.shape), key
        if kind == "state":
            np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=key)
            atol = ROUND_OFF * np.nanmax(np.abs(a)) if a.size else 0.0
            np.testing.assert_allclose(b, a, rtol=0.0, atol=atol, err_msg=key)
        elif kind == "error":
            assert np.all(a <= PROJECTION_TOLERANCE) and np.all(b <= PROJECTION_TOLERANCE), key


class _Stop(Exception):
    pass


def _stop_at_frame_3(simulation: jellysim.Simulation) -> None:
    if simulation.frame == 3:
        raise _Stop


@pytest.mark.skipif(not PINNED, reason=NOT_PINNED)
@pytest.mark.parametrize("name", list(CASES))
def test_an_old_checkpoint_resumes(name: str, tmp_path: Path) -> None:
    preset, overrides = CASES[name]
    scene = jellysim.load_scene(preset, overrides)
    jellysim.run(scene, tmp_path / "whole").close()

    stopped = tmp_path / "stopped"
    with pytest.raises(_Stop):
        jellysim.run(scene, stopped, observers=[_stop_at_frame_3])
    checkpoint = stopped / "checkpoint.npz"
    with np.load(checkpoint) as new, np.load(OLD / f"{name}.npz") as old:
        assert sorted(new.files) == sorted(old.files)  # the same layout
        written = {key: new[key] for key in new.files}
        stored = {key: old[key] for key in old.files}
    assert physics(str(stored["scene"])) == physics(str(written["scene"]))  # the same physics
    _assert_same_but_round_off(stored, written)  # and the same state, but round-off
    # Resume from the old state: its frame and arrays, under the present scene text.
    with np.load(OLD / f"{name}.npz") as old:
        state = {key: old[key] for key in old.files if key not in ("frame", "scene")}
        save_checkpoint(stopped, int(old["frame"]), str(written["scene"]), state)
    jellysim.run(scene, stopped, resume=True).close()
    whole = read_all(tmp_path / "whole" / "result.h5")
    _assert_same_but_round_off(whole, read_all(stopped / "result.h5"))
