"""Tentacles in the simulated water (issue 26): with ``flow.model = "fluid"`` every group of a
Case 2 scene feels the MPS water's velocity at each particle (Eq. S1,
docs/theory/soft-bell.md §8) instead of the paper's assumed 1 m/s flow relative to the bell."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scenes
from faultkit import assert_same_result
from scipy.spatial import cKDTree

import jellysim
from jellysim.fluid.geometry import FLUID

OVERRIDES = {
    **scenes.SMALL_MOON,
    "duration": 0.3,
    "fps": 10.0,
    "tentacles.count": 2,
    "flow.noise": 0.0,
    "flow.speed": 1.0,
}
FRAMES = 3


def run(flow_model: str) -> tuple[jellysim.Simulation, list[tuple[np.ndarray, np.ndarray]]]:
    """Three frames of the small moon jelly; the sampler's calls (points, water) when the flow
    is the fluid's."""
    scene = jellysim.load_scene("moon-jelly", {**OVERRIDES, "flow.model": flow_model})
    simulation = jellysim.Simulation(scene)
    simulation.prepare()
    tentacles = simulation.tentacles  # type: ignore[attr-defined]
    calls: list[tuple[np.ndarray, np.ndarray]] = []
    sample = tentacles.water_sampler
    if sample is not None:

        def recording(points: np.ndarray) -> np.ndarray:
            water = sample(points)
            calls.append((points.copy(), water))
            return water

        tentacles.water_sampler = recording
    for _ in range(FRAMES):
        simulation.step_frame()
    return simulation, calls


def test_each_group_feels_the_simulated_water_at_its_particles() -> None:
    fluid, calls = run("fluid")
    tentacles = fluid.tentacles  # type: ignore[attr-defined]
    groups = tentacles.groups
    assert len(calls) == FRAMES * len(groups)  # once a frame per group, at every particle
    sizes = [g.positions.shape[0] * g.positions.shape[1] for g in groups]
    assert [len(points) for points, _ in calls] == sizes * FRAMES
    waters = np.concatenate([water for _, water in calls])
    assert np.all(np.isfinite(waters))
    # The bell starts its first pulse from rest: the water around the tentacles stirs, far
    # below the paper's assumed 1 m/s.
    assert 0.0 < np.abs(waters).max() < 0.5
    # So the tentacles, released in their rest shape, move far less than in the assumed flow.
    paper, none = run("bell")
    assert none == []
    speed_fluid = np.nanmean(np.linalg.norm(tentacles.velocities, axis=2))
    speed_paper = np.nanmean(np.linalg.norm(paper.tentacles.velocities, axis=2))  # type: ignore[attr-defined]
    assert speed_fluid < 0.5 * speed_paper


def test_two_way_the_water_receives_what_the_tentacles_took() -> None:
    """``flow.two_way``: each frame the drag impulse on the tentacles goes back to the water,
    equal and opposite (Eq. S2), as a force density over the next frame's MPS steps, which
    adds exactly that momentum to the water and the bell (m = rho l0^3, and the steps' lengths
    add up to the frame)."""
    scene = jellysim.load_scene(
        "moon-jelly", {**OVERRIDES, "flow.model": "fluid", "flow.two_way": True}
    )
    simulation = jellysim.Simulation(scene)
    simulation.prepare()
    coupling = simulation.coupling  # type: ignore[attr-defined]
    taken: list[np.ndarray] = []
    take = coupling.take_reaction

    def recording(points: np.ndarray, impulses: np.ndarray, frame_dt: float) -> None:
        take(points, impulses, frame_dt)
        # The points with water (or bell) within r_e; the small scene's arm tips poke out
        # through the tank's floor, and their reaction has nothing to act on.
        solver = coupling.solver
        water = solver.position[solver.alive & (solver.kind == FLUID)]
        distance, _ = cKDTree(water).query(points)
        wet = distance < solver.constants.re_number_density
        taken.append(impulses[wet].sum(axis=0))
        given = coupling.reaction.sum(axis=0) * frame_dt * coupling._cell_volume
        np.testing.assert_allclose(given, -taken[-1], rtol=1e-12, atol=1e-18)

    simulation.tentacles.water_reaction = lambda p, j: recording(p, j, simulation.frame_dt)  # type: ignore[attr-defined]
    for _ in range(FRAMES):
        simulation.step_frame()
    assert len(taken) == FRAMES
    assert np.abs(taken[-1]).max() > 0.0  # the drag did act
    one_way, _ = run("fluid")
    water = simulation.coupling.solver.velocity  # type: ignore[attr-defined]
    assert not np.array_equal(water, one_way.coupling.solver.velocity)  # type: ignore[attr-defined]


def test_two_way_resumes_bit_for_bit(tmp_path: Path) -> None:
    """The reaction still to act is part of the checkpoint."""
    scene = jellysim.load_scene(
        "moon-jelly",
        {**OVERRIDES, "duration": 0.4, "flow.model": "fluid", "flow.two_way": True,
         "solver.checkpoint_every": 2},
    )  # fmt: skip

    def abort(simulation: jellysim.Simulation) -> None:
        if simulation.frame == 3:
            raise _Abort

    with pytest.raises(_Abort):
        jellysim.run(scene, tmp_path / "stopped", observers=[abort])
    with np.load(tmp_path / "stopped" / "checkpoint.npz") as checkpoint:
        assert "coupling_reaction" in checkpoint.files
    jellysim.run(scene, tmp_path / "stopped", resume=True).close()
    jellysim.run(scene, tmp_path / "whole").close()
    assert_same_result(tmp_path / "stopped", tmp_path / "whole")


class _Abort(Exception):
    pass
