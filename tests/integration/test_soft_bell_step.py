"""The soft bell's fluid step (docs/soft-bell.md, "The time step under gravity"): under gravity the
water steps at kappa sqrt(l0 / g) from rest, not at the fluid-only scenes' free fall over the
water's height; in weightless water the particles' speed alone sets it."""

from __future__ import annotations

import math

import pytest
import scenes

import jellysim
from jellysim.coupling.bell_in_fluid import STILL_WATER_ACCELERATION_NUMBER


@pytest.mark.parametrize(
    ("overrides", "spacing", "steps"),
    [({}, 0.16, 12), (scenes.SWIM, 0.25, 18)],
    ids=["preset", "coarse-test"],
)
def test_under_gravity_the_step_is_the_still_water_bound(
    overrides: dict[str, object], spacing: float, steps: int
) -> None:
    """12 steps a 1/20 s frame at the preset's l0 = 0.16 m (a free fall over the water's 5.76 m
    would take 17) and the 18 a 1/10 s frame that the coarse gravity test was validated at."""
    moon = jellysim.Simulation(jellysim.load_scene("moon-jelly", overrides))
    dt = moon.coupling.solver.stable_dt()
    assert dt == pytest.approx(STILL_WATER_ACCELERATION_NUMBER * math.sqrt(spacing / 9.81))
    assert math.ceil(moon.frame_dt / dt) == steps
    assert not moon.coupling.solver.params.free_fall_floor


def test_in_weightless_water_the_particles_speed_sets_the_step() -> None:
    moon = jellysim.Simulation(jellysim.load_scene("moon-jelly-weightless", scenes.SMALL_MOON))
    solver = moon.coupling.solver
    p = solver.params
    solver.velocity[0] = [0.0, 0.0, 0.5]  # the fastest water particle, m/s
    assert solver.stable_dt() == p.courant * p.l0 / 0.5
    solver.velocity[:] = 0.0  # at rest only viscosity bounds the step: no floor, no gravity
    assert solver.stable_dt() == p.diffusion_number * p.l0**2 / p.kinematic_viscosity
