"""The substep plan (docs/theory/tentacle.md §5): chosen by the code, scaled by dt_safety."""

import pytest

import jellysim
from jellysim.bell import make_root_driver
from jellysim.errors import InputError
from jellysim.tentacle.model import plan_substeps


def plan(**overrides):
    scene = jellysim.load_scene("brown-jelly", overrides)
    return plan_substeps(scene, make_root_driver(scene).forcing())


def test_substeps_fill_the_frame_exactly():
    for fps in (30.0, 7.0):
        for modulus in (1e2, 9e9):
            p = plan(fps=fps, **{"tentacles.youngs_modulus": modulus})
            assert p.dt * p.substeps == pytest.approx(1 / fps, rel=1e-12)
            assert p.dt <= min(p.limits.values()) * (1 + 1e-12)


def test_stiff_rods_get_a_bending_limited_but_affordable_substep():
    # Straight at rest: a curled stiff rod is limited by its explicit rest force instead
    # (docs/theory/tentacle.md §6, test_a_curl_limits_the_substep_of_a_stiff_rod below).
    straight = {"tentacles.rest_curvature": 0.0, "tentacles.rest_curvature_tip": 0.0}
    soft = plan(**straight)
    wood = plan(**straight, **{"tentacles.youngs_modulus": 9e9})
    assert min(soft.limits, key=soft.limits.get) != "bending"
    assert min(wood.limits, key=wood.limits.get) == "bending"
    assert wood.dt < soft.dt
    assert wood.dt > 100 * 5e-6  # an explicit step would need about 5 microseconds


def test_a_curl_limits_the_substep_of_a_stiff_rod():
    # brown-jelly curls its tentacles (issue 25): at 9 GPa the explicit rest force binds
    # (docs/theory/tentacle.md §6), at the preset's 100 Pa it does not.
    straight = {"tentacles.rest_curvature": 0.0, "tentacles.rest_curvature_tip": 0.0}
    wood = {"tentacles.youngs_modulus": 9e9}
    curled, plain = plan(**wood), plan(**straight, **wood)
    assert min(curled.limits, key=curled.limits.get) == "rest shape"
    assert "rest shape" not in plain.limits or plain.limits["rest shape"] > plain.dt
    assert curled.dt < plain.dt
    soft = plan()
    assert min(soft.limits, key=soft.limits.get) != "rest shape"


def test_dt_safety_scales_the_substep():
    for safety in (0.5, 0.1):
        p = plan(**{"solver.dt_safety": safety})
        assert p.dt <= safety * min(p.limits.values()) * (1 + 1e-12)
        assert p.substeps >= 2  # the frame limit does not bind here


def test_faster_flows_get_shorter_substeps():
    assert plan(**{"flow.speed": 10.0}).dt < plan(**{"flow.speed": 0.3}).dt


def test_an_unaffordable_substep_is_an_input_error():
    with pytest.raises(InputError, match="substeps per frame"):
        plan(**{"tentacles.youngs_modulus": 1e13, "tentacles.particles": 3, "fps": 0.01})
