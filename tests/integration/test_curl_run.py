"""Natural curl (issue 25) through the command line, the result and a resumed run."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from regression.compare import differences, read_all

import jellysim
from jellysim.cli.main import main

CURL = {
    "duration": 0.4,
    "tentacles.count": 2,
    "tentacles.rest_curvature": 20.0,
    "tentacles.rest_curvature_tip": 40.0,
    "tentacles.rest_torsion": 10.0,
    "solver.checkpoint_every": 3,
}


def test_cli_set_rest_curvature_coils_the_tentacles(tmp_path: Path) -> None:
    out = tmp_path / "curl"
    status = main(
        [
            "run",
            "forced-tentacles",
            "--set",
            "tentacles.rest_curvature=30",
            "--set",
            "duration=0.2",
            "--set",
            "flow.speed=0",
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert status == 0
    with h5py.File(out / "result.h5", "r") as f:
        x = f["tentacles/position"][()]
        assert "rest_curvature = 30.0" in f.attrs["scene"]
    length = 59 * 0.01
    chord = np.linalg.norm(x[:, :, -1] - x[:, :, 0], axis=-1) / length
    # 1.8 rad of curl over 59 segments: the chord of the rest coil is 0.2 of the length; the
    # still water and the forced root (3 cm) hardly change it in 0.2 s.
    assert np.all(chord < 0.3)
    assert np.all(np.abs(np.diff(chord, axis=0)) < 0.05)
    segments = np.linalg.norm(np.diff(x, axis=2), axis=-1)
    np.testing.assert_allclose(segments, 0.01, rtol=1e-9)


class _Stop(Exception):
    pass


def _stop_at_frame_4(simulation: jellysim.Simulation) -> None:
    if simulation.frame == 4:
        raise _Stop


@pytest.mark.parametrize("preset", ["forced-tentacles", "brown-jelly"])
def test_a_curled_run_resumes_bit_for_bit(preset: str, tmp_path: Path) -> None:
    # The rest shape is scene data, rebuilt on resume; only positions and velocities are state.
    scene = jellysim.load_scene(preset, CURL)
    jellysim.run(scene, tmp_path / "whole").close()
    stopped = tmp_path / "stopped"
    with pytest.raises(_Stop):
        jellysim.run(scene, stopped, observers=[_stop_at_frame_4])
    with np.load(stopped / "checkpoint.npz") as checkpoint:
        assert sorted(checkpoint.files) == ["frame", "positions", "scene", "velocities"]
    jellysim.run(scene, stopped, resume=True).close()
    whole = read_all(tmp_path / "whole" / "result.h5")
    assert differences(whole, read_all(stopped / "result.h5")) == []
