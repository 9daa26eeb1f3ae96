"""Tentacle groups (issue 25, docs/groups.md): the scene keys, the root layout, and the groups'
independence in the simulation.

A one-table scene is one group named "tentacles" and runs exactly as before (the regression
references in tests/regression hold every stored array bit for bit). Here: a named group's keys
over the shared ones, ``--set tentacles.GROUP.KEY``, the bad inputs the issue lists, the
layouts' angles, and that a group in a jellyfish with several groups moves exactly as it would
alone (groups do not act on each other; the first keeps the scene's noise stream).
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest

import jellysim
from jellysim.config import load_scene, scene_from_tree, scene_to_toml
from jellysim.config.load import parse_toml
from jellysim.errors import InputError
from jellysim.simulation.tentacles import TentacleSimulation, group_seed
from jellysim.tentacle.layout import group_angles, root_layout
from jellysim.tentacle.model import plan_substeps

BELL = {
    "model": "kinematic",
    "radius": 0.15,
    "height": 0.1,
    "contraction": 0.2,
    "period": 1.0,
    "swim_speed": 0.05,
    "lobes": 16,
    "lobe_depth": 0.05,
}


def tree(**groups: dict) -> dict:
    """A jellyfish with shared tentacle keys and the given groups."""
    return {
        "name": "groups",
        "duration": 0.5,
        "fps": 20.0,
        "flow": {"speed": 0.05, "noise": 0.02},
        "tentacles": {"spacing": 0.01, "youngs_modulus": 200.0, **groups},
        "bell": dict(BELL),
    }


MARGINAL = {"count": 6, "particles": 30, "rest_curvature": 3.0}
ARMS = {
    "count": 4,
    "particles": 20,
    "placement": "mouth",
    "youngs_modulus": 5.0e6,
    "form": "ribbon",
    "angle_offset": 45.0,
}


def test_a_group_takes_the_shared_keys_it_does_not_set() -> None:
    scene = scene_from_tree(tree(marginal=MARGINAL, arms=ARMS))
    names = [g.name for g in scene.groups]
    assert names == ["marginal", "arms"]
    marginal, arms = (g.tentacles for g in scene.groups)
    assert marginal.youngs_modulus == 200.0 and arms.youngs_modulus == 5.0e6
    assert marginal.spacing == arms.spacing == 0.01
    assert arms.rest_curvature is None and marginal.rest_curvature == 3.0
    assert scene.tentacle_count == 10
    assert scene.particle_count == 6 * 30 + 4 * 20
    assert scene.max_particles == 30


def test_a_grouped_scene_round_trips_through_its_toml() -> None:
    scene = scene_from_tree(tree(marginal=MARGINAL, arms=ARMS))
    text = scene_to_toml(scene)
    assert "[tentacles.marginal]" in text and "[tentacles.arms]" in text
    assert scene_from_tree(parse_toml(text, "round trip")) == scene


def test_a_one_table_scene_is_one_group_named_tentacles() -> None:
    scene = load_scene("forced-tentacles")
    assert [g.name for g in scene.groups] == ["tentacles"]
    assert scene.groups[0].tentacles is scene.tentacles
    assert "[tentacles." not in scene_to_toml(scene)


def test_set_reaches_a_key_of_a_named_group() -> None:
    scene = load_scene(
        scene_from_tree(tree(marginal=MARGINAL, arms=ARMS)), {"tentacles.arms.count": 8}
    )
    assert [g.tentacles.count for g in scene.groups] == [6, 8]


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"tentacles.armz.count": 3}, "unknown tentacle group 'armz' (did you mean 'arms'?)"),
        ({"tentacles.arms.cuont": 3}, "unknown key 'tentacles.arms.cuont'"),
        ({"tentacles.arms.count": 0}, "tentacles.arms.count = 0 gives the group no roots"),
        ({"tentacles.arms.mouth_radius": 0.9}, "the arms do not fit under the bell"),
        (
            {"tentacles.marginal.rest_curvature": 60.0},
            "tentacles.marginal.rest_curvature = 60.0 is too tight",
        ),
        ({"tentacles.marginal.angles": [0.0, 90.0]}, "gives 2 angles for"),
        (
            {"tentacles.marginal.arrangement": "clusters", "tentacles.marginal.clusters": 9},
            "every cluster needs a root",
        ),
        ({"tentacles.arms.form": "rope"}, "tentacles.arms.form = 'rope' is not allowed"),
    ],
)
def test_bad_group_input_names_the_key(overrides: dict, message: str) -> None:
    base = scene_from_tree(tree(marginal=MARGINAL, arms=ARMS))
    with pytest.raises(InputError) as caught:
        load_scene(base, overrides)
    text = str(caught.value)
    assert message in text
    assert len(text.splitlines()) <= 3


def test_set_on_a_one_table_scene_names_no_group() -> None:
    with pytest.raises(InputError, match="has no tentacle group 'arms'"):
        load_scene(load_scene("brown-jelly").group_scene(0), {"tentacles.arms.count": 4})


def test_a_shared_key_every_group_sets_is_refused() -> None:
    with pytest.raises(InputError, match="changes nothing: every tentacle group sets count"):
        load_scene(scene_from_tree(tree(marginal=MARGINAL, arms=ARMS)), {"tentacles.count": 3})


@pytest.mark.parametrize(
    ("groups", "message"),
    [
        ({"count": {"particles": 3}}, "tentacles.count is a key of [tentacles], not a group"),
        ({"2arms": {"count": 2}}, "'2arms' is not a group name"),
        ({"arms": {"count": 2, "inner": {"count": 1}}}, "groups do not nest"),
    ],
)
def test_bad_group_tables(groups: dict, message: str) -> None:
    with pytest.raises(InputError) as caught:
        scene_from_tree(tree(**groups))
    assert message in str(caught.value)


def test_even_layout_is_the_one_table_scenes() -> None:
    # The bell models placed root k at 2 pi k / T; the layout gives the same numbers bit for bit.
    scene = load_scene("brown-jelly").group_scene(0)  # its marginal tentacles: one table
    count = scene.tentacles.count
    np.testing.assert_array_equal(root_layout(scene).angles, 2.0 * np.pi * np.arange(count) / count)
    assert root_layout(scene).default


def test_cluster_layout_shares_roots_among_clusters() -> None:
    scene = scene_from_tree(
        tree(
            fringe={
                "count": 20,
                "particles": 5,
                "arrangement": "clusters",
                "clusters": 8,
                "cluster_spread": 10.0,
            }
        )
    )
    angles = np.degrees(group_angles(scene.groups[0].tentacles))
    # 20 over 8 clusters: the first four get 3, the others 2; centred on 0, 45, 90 ... degrees.
    sizes = [3, 3, 3, 3, 2, 2, 2, 2]
    edges = np.cumsum([0, *sizes])
    for j, (a, b) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
        cluster = angles[a:b]
        assert cluster.mean() == pytest.approx(45.0 * j, abs=1e-9)
        assert cluster.max() - cluster.min() == pytest.approx(10.0, abs=1e-9)


def test_given_angles_and_offset() -> None:
    scene = scene_from_tree(
        tree(arms={"count": 3, "angles": [0.0, 30.0, 200.0], "angle_offset": 10.0})
    )
    np.testing.assert_allclose(np.degrees(root_layout(scene).angles), [10.0, 40.0, 210.0])


def test_mouth_roots_hang_under_the_bell_inside_the_margin() -> None:
    scene = scene_from_tree(tree(marginal=MARGINAL, arms={**ARMS, "mouth_radius": 0.2}))
    sim = TentacleSimulation(scene)
    times = np.linspace(0.0, 1.0, 9)
    roots, _, directions = sim.driver.roots(times)
    arms = roots[:, 6:]
    margin = roots[:, :6]
    centre_z = margin[..., 2].mean(axis=1)
    np.testing.assert_allclose(np.hypot(arms[..., 0], arms[..., 1]), 0.2 * 0.15, rtol=1e-12)
    np.testing.assert_allclose(arms[..., 2] - centre_z[:, None], 0.0, atol=1e-12)  # margin plane
    np.testing.assert_allclose(directions[:, 6:], [[[0.0, 0.0, -1.0]] * 4] * 9)
    # Inside the most contracted margin: the bell never closes on its arms.
    assert (
        np.hypot(arms[..., 0], arms[..., 1]).max() < np.hypot(margin[..., 0], margin[..., 1]).min()
    )


def test_a_group_moves_as_it_would_alone() -> None:
    # Groups do not act on each other: the first group of a two-group jellyfish (same roots,
    # the scene's noise stream) matches a one-table scene of its keys bit for bit.
    grouped = scene_from_tree(tree(marginal=MARGINAL, arms=ARMS))
    alone_tree = tree()
    alone_tree["tentacles"].update(MARGINAL)
    alone = scene_from_tree(alone_tree)
    a, b = TentacleSimulation(grouped), TentacleSimulation(alone)
    for _ in range(6):
        a.step_frame()
        b.step_frame()
    np.testing.assert_array_equal(a.groups[0].positions, b.positions)
    np.testing.assert_array_equal(a.groups[0].velocities, b.velocities)
    # The state gathered for the result: the arms' rows beyond their 20 particles are NaN.
    positions = a.positions
    assert positions.shape == (10, 30, 3)
    assert np.isnan(positions[6:, 20:]).all()
    assert np.isfinite(positions[:6]).all() and np.isfinite(positions[6:, :20]).all()


def test_each_group_has_its_own_noise_stream() -> None:
    assert group_seed(7, 0) == 7
    seeds = {group_seed(7, g) for g in range(1, 6)}
    assert len(seeds) == 5 and 7 not in seeds
    assert all(0 <= s < 2**63 for s in seeds)


def test_each_group_plans_its_own_substep() -> None:
    # E = 5 MPa arms bend on a far shorter time scale than E = 200 Pa tentacles; each group's
    # plan comes from its own keys, as a one-table scene of them would plan it.
    scene = scene_from_tree(tree(marginal=MARGINAL, arms=ARMS))
    sim = TentacleSimulation(scene)
    soft, stiff = (g.plan for g in sim.groups)
    assert stiff.limits["bending"] < 0.01 * soft.limits["bending"]
    forcing = sim.driver.forcing()
    for index, group in enumerate(sim.groups):
        assert group.plan == plan_substeps(scene.group_scene(index), forcing)


def test_a_grouped_run_writes_groups_and_resumes_bit_for_bit(tmp_path) -> None:
    scene = load_scene(scene_from_tree(tree(marginal=MARGINAL, arms=ARMS)), {"duration": 1.0})
    jellysim.run(scene, out=tmp_path / "whole").close()
    with h5py.File(tmp_path / "whole" / "result.h5", "r") as f:
        assert list(f.attrs["tentacle_groups"]) == ["marginal", "arms"]
        np.testing.assert_array_equal(f["tentacles/group"][()], [0] * 6 + [1] * 4)
        np.testing.assert_array_equal(f["tentacles/particles"][()], [30] * 6 + [20] * 4)
        expected = f["tentacles/position"][()]
        whole_velocity = f["tentacles/velocity"][()]
    assert expected.shape == (21, 10, 30, 3)
    assert np.isnan(expected[:, 6:, 20:]).all()
    assert np.isfinite(expected[:, :, :20]).all()
    # Abort after the checkpoint at frame 8 and resume: the same result, bit for bit.
    part = load_scene(scene, {"solver.checkpoint_every": 8})

    def abort(simulation: jellysim.Simulation) -> None:
        if simulation.frame == 13:
            raise Aborted

    with pytest.raises(Aborted):
        jellysim.run(part, out=tmp_path / "part", observers=[abort])
    jellysim.run(part, out=tmp_path / "part", resume=True).close()
    with h5py.File(tmp_path / "part" / "result.h5", "r") as f:
        np.testing.assert_array_equal(f["tentacles/position"][()], expected)
        np.testing.assert_array_equal(f["tentacles/velocity"][()], whole_velocity)


class Aborted(Exception):
    """Stops a run from an observer."""
