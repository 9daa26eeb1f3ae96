"""The preset moon-jelly-fine (issue 28: "a bell at least six particles thick in at least a million
water particles"), checked on the particles the real set-up code builds (the tank and water of
:func:`jellysim.fluid.setup.fluid_particles`, the bell's shell of Eq. B7 carved out of them as
:class:`jellysim.coupling.bell_in_fluid.BellInFluid` carves it, the springs of
:class:`jellysim.bell.soft.SoftBell`) and against moon-jelly, the same jellyfish on a lattice three
times coarser. Its three pulses on a GPU: tests/gpu/test_gpu.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

import jellysim
from jellysim.bell.soft import BellShape, SoftBell
from jellysim.coupling.bell_in_fluid import STILL_WATER_ACCELERATION_NUMBER
from jellysim.fluid.geometry import FLUID
from jellysim.fluid.setup import fluid_particles
from jellysim.simulation.estimate import fluid_plan, particle_counts

FINE = "moon-jelly-fine"
# The wall in particle layers (w / l0) and the bell's and water's particles at each spacing.
LATTICES = {"moon-jelly": (2, 1_076, 56_524), FINE: (6, 28_744, 1_526_456)}


def carved(name: str) -> tuple[jellysim.Scene, BellShape, np.ndarray, np.ndarray]:
    """The preset's scene, bell shape, fluid lattice sites (N, 3) m and which of them are the
    bell's (N,) bool."""
    scene = jellysim.load_scene(name)
    positions, kinds, _ = fluid_particles(scene)
    fluid = positions[kinds == FLUID]
    shape = BellShape(scene)
    return scene, shape, fluid, shape.shell(fluid)


def test_the_fine_preset_is_moon_jelly_at_a_third_of_its_spacing() -> None:
    """Only the spacing, the spring constant, the run's length and the CPU's neighbour lists
    differ; the spring constant keeps k / l0, and with it the network's Young's modulus
    E_eff = 19.7 k / l0 (docs/theory/soft-bell.md §2): the same material. The fine preset keeps
    no Verlet skin (its lists would take twice the memory on the CPU), where moon-jelly keeps
    0.3 l0: the same flow at round-off."""
    fine, moon = jellysim.load_scene(FINE), jellysim.load_scene("moon-jelly")
    assert (fine.fluid.neighbour_skin, moon.fluid.neighbour_skin) == (0.0, 0.3)
    changed = {
        "name": FINE,
        "duration": fine.duration,
        "fluid.spacing": fine.fluid.spacing,
        "bell.spring_stiffness": fine.bell.spring_stiffness,
        "fluid.neighbour_skin": fine.fluid.neighbour_skin,
    }
    assert jellysim.load_scene("moon-jelly", changed) == fine
    assert fine.fluid.spacing == pytest.approx(moon.fluid.spacing / 3, rel=1e-15)
    assert fine.bell.spring_stiffness / fine.fluid.spacing == pytest.approx(
        moon.bell.spring_stiffness / moon.fluid.spacing, rel=1e-15
    )
    assert fine.duration == 3 * fine.bell.period  # "three pulses"
    assert fine.fluid.device == "cpu"  # --device cuda chooses the GPU


@pytest.mark.parametrize("name", list(LATTICES))
def test_the_water_and_the_wall_on_the_lattice(name: str) -> None:
    """The bell's and the water's particles, and the wall's thickness counted in bell cells: the
    columns of cells on the axis at the apex and the rows along x and y at the margin, on both
    sides, each cross exactly w / l0 of them (2 in moon-jelly, 6 in moon-jelly-fine)."""
    layers, bell_particles, water_particles = LATTICES[name]
    scene, shape, fluid, in_bell = carved(name)
    l0 = scene.fluid.spacing
    assert shape.wall / l0 == pytest.approx(layers, rel=1e-12)
    assert int(in_bell.sum()) == bell_particles
    assert int((~in_bell).sum()) == water_particles
    # Cell indices relative to the axis, which runs along cell faces (the tank's centre).
    cell = np.floor((fluid[in_bell] - shape.centre) / l0 + 1e-9).astype(np.int64)
    apex = cell[np.isin(cell[:, 0], (-1, 0)) & np.isin(cell[:, 1], (-1, 0))]
    columns, per_column = np.unique(apex[:, :2], axis=0, return_counts=True)
    assert len(columns) == 4 and np.all(per_column == layers)
    margin = cell[cell[:, 2] == 0]  # the lowest layer, half a spacing above the margin plane
    for along, across in ((0, 1), (1, 0)):
        row = margin[margin[:, across] == 0]
        assert np.sum(row[:, along] >= 0) == np.sum(row[:, along] < 0) == layers
    if name == FINE:
        assert water_particles >= 1_000_000 and layers >= 6  # issue 28


@pytest.mark.parametrize(("name", "thinnest"), [("moon-jelly", 1.85), (FINE, 5.56)])
def test_the_shell_is_thinnest_at_its_shoulder(name: str, thinnest: float) -> None:
    """Eq. B7's shell lies between the half-ellipses (R, H) and (R - w, H - w): w thick at the
    apex and at the margin, 0.927 w normal to the wall at its thinnest, 37 degrees up from the
    margin (docs/decisions.md, "moon-jelly-fine"): 1.85 l0 in moon-jelly, 5.56 l0 here."""
    scene = jellysim.load_scene(name)
    shape = BellShape(scene)
    angle = np.linspace(0.0, 0.5 * math.pi, 200_001)
    inner_r, inner_h = shape.radius - shape.wall, shape.height - shape.wall
    inner = np.stack([inner_r * np.cos(angle), inner_h * np.sin(angle)], axis=1)
    outer = np.stack([shape.radius * np.cos(angle), shape.height * np.sin(angle)], axis=1)
    distance, _ = cKDTree(inner).query(outer[::100])
    assert distance.min() / scene.fluid.spacing == pytest.approx(thinnest, abs=0.005)
    at = outer[::100][np.argmin(distance)]
    assert math.degrees(math.atan2(at[1] / shape.height, at[0] / shape.radius)) == (
        pytest.approx(37.0, abs=1.0)
    )


def test_the_fine_wall_is_mostly_bulk_material() -> None:
    """The springs of moon-jelly-fine's bell (663,724; 2.4 l0 reaches 56 lattice neighbours): its
    wall has particles with the whole neighbourhood of the bulk, for which E_eff = 19.7 k / l0
    holds, and 46 springs a particle on average, where moon-jelly's two layers have 28 and none
    with 56."""
    springs = {}
    for name in LATTICES:
        scene, shape, fluid, in_bell = carved(name)
        body = SoftBell(scene, shape, fluid[in_bell])
        springs[name] = np.bincount(body.springs.pairs.ravel(), minlength=len(body.rest))
    assert springs[FINE].sum() // 2 == 663_724
    assert springs[FINE].max() == 56 and springs["moon-jelly"].max() < 56
    assert springs[FINE].mean() == pytest.approx(46.2, abs=0.05)
    assert springs["moon-jelly"].mean() == pytest.approx(28.0, abs=0.05)


def test_three_pulses_take_2400_mps_steps() -> None:
    """Under gravity the soft bell's step is kappa sqrt(l0 / g) (docs/soft-bell.md, "The time
    step under gravity"): 20 steps a 1/20 s frame at l0 = 0.16 m / 3 (12 in moon-jelly), 2,400
    for the three pulses, which issue 28's ten minutes on a GPU make 4 steps a second."""
    scene = jellysim.load_scene(FINE)
    plan = fluid_plan(scene, particle_counts(scene))
    assert plan.dt == pytest.approx(
        STILL_WATER_ACCELERATION_NUMBER * math.sqrt(scene.fluid.spacing / 9.81), rel=1e-12
    )
    assert plan.steps == 20
    assert plan.steps * round(scene.duration * scene.fps) == 2_400
