"""A uniform current in the world frame, from any side (issue 26): ``flow.model = "current"``
blows the tentacles along ``flow.direction`` whatever the bell does, as the paper's flow
(``flow.model = "bell"``, the default) blows them from root to tip along the bell's axis."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

import jellysim
from jellysim.config.load import scene_from_tree
from jellysim.io.plots import flow_label
from jellysim.tentacle.flow import current_direction, flow_at_tentacles

# forced-tentacles: roots on a still ring, clamped downwards, in the paper's flow along the axis.
SMALL = {"duration": 1.0, "tentacles.count": 2, "flow.noise": 0.0}


def tip_drift(tmp_path: Path, overrides: dict[str, object]) -> np.ndarray:
    """Mean displacement (3,) m of the tips from their roots at the last frame."""
    scene = jellysim.load_scene("forced-tentacles", {**SMALL, **overrides})
    with jellysim.run(scene, out=tmp_path, force=True, quiet=True) as result:
        positions = result.tentacle_positions[-1]
    return np.mean(positions[:, -1] - positions[:, 0], axis=0)


@pytest.mark.parametrize("direction", [(1.0, 0.0, 0.0), (0.0, -2.0, 0.0)])
def test_a_current_blows_the_tentacles_its_way(tmp_path: Path, direction) -> None:
    unit = np.asarray(direction) / np.linalg.norm(direction)
    drift = tip_drift(
        tmp_path,
        {"flow.model": "current", "flow.direction": list(direction), "flow.speed": 0.3},
    )
    assert drift @ unit > 0.3 * np.linalg.norm(drift)  # pushed downstream, sideways
    still = tip_drift(tmp_path, {"flow.model": "current", "flow.speed": 0.0})
    assert abs(still @ unit) < 0.05 * np.linalg.norm(still)  # no current: they hang


def test_the_current_ignores_the_bell_and_the_bell_flow_follows_it() -> None:
    times = 3
    axis = np.tile([0.0, 0.0, 1.0], (times, 1))
    bell_velocity = np.tile([0.0, 0.0, 0.2], (times, 1))
    noise = np.zeros((times, 2, 3))
    tree = {"flow": {"model": "current", "speed": 0.5, "direction": [0.0, 3.0, 4.0]}}
    current = flow_at_tentacles(scene_from_tree(tree).flow, axis, bell_velocity, noise)
    np.testing.assert_allclose(current, np.broadcast_to([0.0, 0.3, 0.4], (times, 2, 3)))
    paper = flow_at_tentacles(scene_from_tree({}).flow, axis, bell_velocity, noise)
    np.testing.assert_allclose(paper, np.broadcast_to([0.0, 0.0, 0.2 - 0.3], (times, 2, 3)))


def test_the_result_records_the_water_and_the_drag_law(tmp_path: Path) -> None:
    overrides = {
        **SMALL,
        "duration": 0.1,
        "flow.model": "current",
        "tentacles.drag": "slender",
    }
    scene = jellysim.load_scene("forced-tentacles", overrides)
    with jellysim.run(scene, out=tmp_path / "current", force=True) as result:
        assert result.tentacle_flow == "current"
        assert result.tentacle_drag == ["slender"]
    scene = jellysim.load_scene("forced-tentacles", {**SMALL, "duration": 0.1})
    with jellysim.run(scene, out=tmp_path / "paper", force=True) as result:
        assert (result.tentacle_flow, result.tentacle_drag) == ("bell", ["sphere"])
    with h5py.File(tmp_path / "current" / "result.h5", "r+") as f:  # as written before issue 26
        del f.attrs["tentacle_flow"], f.attrs["tentacle_drag"]
    with jellysim.open_result(tmp_path / "current") as result:
        assert (result.tentacle_flow, result.tentacle_drag) == ("bell", ["sphere"])


def test_flow_labels_name_the_water() -> None:
    current = scene_from_tree({"flow": {"model": "current", "speed": 0.5, "direction": [0, 1, 0]}})
    assert flow_label(current) == "current 0.5 m/s along (0, 1, 0)"
    assert flow_label(scene_from_tree({})) == "v = 0.3 m/s"


def test_a_direction_of_any_finite_size_is_normalised_without_overflow() -> None:
    np.testing.assert_allclose(current_direction((1e-200, 0.0, 0.0)), [1.0, 0.0, 0.0])
    np.testing.assert_allclose(current_direction((1e300, -1e300, 0.0)), [0.5**0.5, -(0.5**0.5), 0])
