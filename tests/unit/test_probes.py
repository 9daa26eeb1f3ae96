"""Obstacles and probes (issue 28, SPHERIC Test 2): the box's particles, the height probe on still
water against the depth the lattice fills, the pressure probe against a known field and its
face, and the scene's keys."""

from __future__ import annotations

import numpy as np
import pytest

import jellysim
from jellysim.config.load import scene_to_toml, wall_distance
from jellysim.errors import InputError
from jellysim.fluid.geometry import (
    DUMMY,
    FLUID,
    WALL,
    box_obstacle,
    filled_height,
    tank,
    water_block,
)
from jellysim.fluid.probes import HeightProbes, PressureProbes, face_of
from jellysim.fluid.setup import fluid_particles

L0 = 0.161 / 3  # the coarsest spacing of spheric-test2 that divides the tank (docs/decisions.md)
BOX = np.array([0.6635, 0.2985, 0.0, 0.8245, 0.7015, 0.161])


@pytest.mark.parametrize("lattice", ["fcc", "square"])
def test_box_is_walls_over_dummies(lattice: str) -> None:
    sites, kinds = box_obstacle(BOX[:3], BOX[3:], L0, lattice)
    assert len(sites) > 0
    assert np.all((sites >= BOX[:3] - 1e-9) & (sites <= BOX[3:] + 1e-9))
    depth = np.minimum(sites - BOX[:3], BOX[3:] - sites)
    depth[:, 2] = BOX[5] - sites[:, 2]  # on the floor: no wall layer along the bottom
    nearest = depth.min(axis=1)
    assert np.all(nearest[kinds == WALL] < L0)
    assert np.all(nearest[kinds == DUMMY] >= L0 * (1 - 1e-9))
    assert (kinds == DUMMY).any()


def test_preset_geometry() -> None:
    """spheric-test2 at 3 spacings a box: the water against the far wall from the gate at
    x = 1.992, the box's particles inside it, clear of the water and of the tank's."""
    scene = jellysim.load_scene("spheric-test2", {"fluid.spacing": L0})
    positions, kinds, attributes = fluid_particles(scene)
    water = positions[kinds == FLUID]
    assert water[:, 0].min() >= 1.992 and water[:, 0].max() <= 3.22
    assert 3.22 - water[:, 0].max() < L0 and water[:, 0].min() - 1.992 < L0
    inside = np.all((positions >= BOX[:3] - 1e-9) & (positions <= BOX[3:] + 1e-9), axis=1)
    assert not (inside & (kinds == FLUID)).any()
    assert (inside & (kinds == WALL)).sum() > 50
    # no two particles closer than the lattice's spacing (the box's sites are the lattice's own)
    from scipy.spatial import cKDTree

    pairs = cKDTree(positions).query_pairs(0.99 * L0)
    assert not pairs
    assert attributes["column_width"] == pytest.approx(1.228)


@pytest.mark.parametrize("lattice", ["fcc", "square"])
def test_height_probe_reads_still_water(lattice: str) -> None:
    """Eq. (F14) on still water 0.3 m deep reads the depth its layers fill, within 1 %,
    wherever the line stands against the lattice."""
    l0 = 0.02
    water = water_block(0.0, 1.0, 0.0, 1.0, l0, 0.0, 0.3, lattice=lattice)
    kinds = np.full(len(water), FLUID, dtype=np.int8)
    places = np.array([[0.5, 0.5], [0.503, 0.517], [0.3111, 0.7007]])
    depths = HeightProbes(places, l0, 3, lattice).measure(water, kinds, np.ones(len(water), bool))
    expected = filled_height(0.3, l0, lattice)
    np.testing.assert_allclose(depths, expected, rtol=0.01)


def test_height_probe_in_2d_and_dry() -> None:
    l0 = 0.01
    water = water_block(0.0, 0.5, 0.0, 0.2, l0, lattice="hexagonal")
    kinds = np.full(len(water), FLUID, dtype=np.int8)
    probes = HeightProbes(np.array([[0.25], [0.8]]), l0, 2, "hexagonal")
    depth, dry = probes.measure(water, kinds, np.ones(len(water), bool))
    assert depth == pytest.approx(filled_height(0.2, l0, "hexagonal"), rel=0.01)
    assert dry == 0.0


def test_pressure_probe_reads_its_face() -> None:
    """A pressure field that is p = 1000 z on the box's front face and 5e4 elsewhere: P1 on the
    face reads 1000 z of its neighbourhood, P5 on the top (0.021 m from the front edge) reads
    only the top's walls; the frame mean weights steps by dt."""
    walls, wall_kinds = tank(3.22, 1.0, L0, dim=3, inner_depth=1.0, lattice="fcc")
    sites, kinds = box_obstacle(BOX[:3], BOX[3:], L0, "fcc")
    position = np.concatenate([walls, sites])
    kind = np.concatenate([wall_kinds, kinds])
    tank_corner = np.array([3.22, 1.0, 1.0])
    faces = face_of(position, tank_corner, BOX[None, :], 1e-6 * L0)
    front = 5 + 3  # the box's upper-x face: after the tank's 5, its lower x, y, z faces
    top = 5 + 5
    pressure = np.where(faces == front, 1000.0 * position[:, 2], 5e4)
    pressure[faces == top] = 7.0
    points = np.array([[0.8245, 0.5255, 0.061], [0.8035, 0.5255, 0.161]])
    probes = PressureProbes(points, position, kind, L0, tank_corner, BOX[None, :])
    p1, p5 = probes.measure(pressure)
    assert 1000 * 0.0 < p1 < 1000 * 0.161
    assert p1 == pytest.approx(61.0, abs=1000 * L0)
    assert p5 == pytest.approx(7.0)
    probes.add_step(probes.measure(pressure), 0.001)
    probes.add_step(probes.measure(pressure * 3), 0.003)
    mean = probes.frame_mean(lambda: probes.measure(pressure))
    assert mean[1] == pytest.approx(7.0 * 2.5)
    again = probes.frame_mean(lambda: probes.measure(pressure))  # none added: now's
    np.testing.assert_allclose(again, [p1, p5])


def test_wall_distance() -> None:
    scene = jellysim.load_scene("spheric-test2", {"fluid.spacing": L0})
    assert wall_distance(scene, (0.8245, 0.5255, 0.021)) == pytest.approx(0.0, abs=1e-12)
    assert wall_distance(scene, (0.85, 0.5, 0.1)) == pytest.approx(0.0255)
    assert wall_distance(scene, (1.5, 0.5, 0.5)) == pytest.approx(0.5)
    assert wall_distance(scene, (1.5, 0.5, 1.5)) == np.inf


def test_probes_round_trip() -> None:
    """The resolved scene's TOML names every probe as a table and loads back equal; --set
    adds one probe."""
    scene = jellysim.load_scene("spheric-test2", {"probes.height.H9": [2.0, 0.25]})
    names = [name for name, _ in scene.probes.height]
    assert names == ["H1", "H2", "H3", "H4", "H9"]
    text = scene_to_toml(scene)
    assert "[probes.height]" in text
    again = jellysim.load_scene(jellysim.config.load.parse_toml(text, "scene"))
    assert again == scene


def test_no_obstacles_in_a_soft_bell() -> None:
    with pytest.raises(InputError, match="fluid-only"):
        jellysim.load_scene("moon-jelly", {"fluid.obstacles": [[0.0, 0.0, 0.0, 0.1, 0.1, 0.1]]})
