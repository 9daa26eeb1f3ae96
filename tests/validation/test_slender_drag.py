"""The slender drag law (issue 26; docs/theory/tentacle.md, Eq. T14): normal and tangential drag
from the water's velocity across and along the chain, the independence principle with cylinder
coefficients (Hoerner, Fluid-Dynamic Drag, 1965, ch. 3: the normal force of a yawed cylinder
depends on the velocity component across it alone).

A straight, detached chain heavier than water falls rigidly (its ends carry half a particle's
mass and half its drag share), so its terminal velocity follows from the law in closed form:
broadside ``U^2 = pi d g (rho_t - rho_w) / (2 rho_w C_n)``, lengthwise
``U^2 = d g (rho_t - rho_w) / (2 rho_w C_t)``, and tilted it glides sideways with the velocity
that solves ``K(U) U = -W`` for the buoyant weight W.
"""

import math

import numpy as np
import pytest
from scipy.optimize import fsolve

from jellysim.tentacle.contact import no_obstacle
from jellysim.tentacle.kernels import Medium, advance_frame, slender_drag_gains
from jellysim.tentacle.model import build_chain_model

RHO_W, RHO_T, D, MU, G = 1000.0, 1100.0, 0.01, 1e-3, 9.81
C_N, C_T = 1.2, 0.05


def test_gains_split_the_velocity_across_and_along_the_chain():
    t = np.array([0.0, 0.6, 0.8])
    across = np.array([1.0, 0.0, 0.0]) * 2.0  # perpendicular to t
    along = t * 3.0
    k_n, k_t = slender_drag_gains(t, across, D, 0.5, RHO_W, C_N, C_T)
    assert k_n == pytest.approx(0.5 * RHO_W * C_N * D * 0.5 * 2.0, rel=1e-15)
    assert k_t == 0.0
    k_n, k_t = slender_drag_gains(t, along, D, 0.5, RHO_W, C_N, C_T)
    assert k_n == pytest.approx(0.0, abs=1e-12)
    assert k_t == pytest.approx(0.5 * RHO_W * C_T * math.pi * D * 0.5 * 3.0, rel=1e-15)
    k_n, k_t = slender_drag_gains(t, across + along, D, 0.5, RHO_W, C_N, C_T)
    assert (k_n, k_t) == pytest.approx((0.5 * RHO_W * C_N * D, 0.75 * RHO_W * C_T * math.pi * D))


def fall(direction, particles=11, duration=4.0, dt=2e-3):
    """The velocity (P, 3) of a straight free chain along unit ``direction`` after falling
    ``duration`` s from rest under the slender law."""
    model = build_chain_model(
        particles, D, 1e6, RHO_T, root="free", drag="slender", normal_drag=C_N,
        tangential_drag=C_T,
    )  # fmt: skip
    medium = Medium(RHO_W, MU, np.array([0.0, 0.0, -G]), RHO_T)
    x = (np.arange(particles)[:, None] * D * np.asarray(direction))[None].copy()
    v = np.zeros_like(x)
    steps = round(duration / dt)
    zeros = np.zeros((steps, 1, 3))
    diagnostics = np.zeros((1, 3))
    advance_frame(
        x, v, zeros, zeros, zeros + np.array([0.0, 0.0, -1.0]), zeros, np.zeros_like(x),
        zeros[:, :, None], model, medium, dt, diagnostics, np.zeros((1, 0, 3)), no_obstacle(),
    )  # fmt: skip
    assert diagnostics[0, 2] == -1
    return v[0]


def test_broadside_fall_reaches_the_normal_drag_terminal_speed():
    speed = math.sqrt(math.pi * D * G * (RHO_T - RHO_W) / (2.0 * RHO_W * C_N))
    v = fall([1.0, 0.0, 0.0], duration=2.0)
    np.testing.assert_allclose(v[:, 2], -speed, rtol=1e-6)
    np.testing.assert_allclose(v[:, :2], 0.0, atol=1e-9)


def test_lengthwise_fall_reaches_the_tangential_drag_terminal_speed():
    speed = math.sqrt(D * G * (RHO_T - RHO_W) / (2.0 * RHO_W * C_T))
    v = fall([0.0, 0.0, -1.0], duration=6.0)
    np.testing.assert_allclose(v[:, 2], -speed, rtol=1e-6)
    np.testing.assert_allclose(v[:, :2], 0.0, atol=1e-9)


def test_a_tilted_chain_glides_as_the_independence_principle_says():
    tilt = math.radians(30.0)
    t = np.array([math.cos(tilt), 0.0, -math.sin(tilt)])
    weight = (RHO_T - RHO_W) * math.pi * D**3 / 4.0 * G  # per interior particle, per length d

    def balance(velocity_xz):
        u = np.array([velocity_xz[0], 0.0, velocity_xz[1]])
        along = u @ t
        normal = u - along * t
        force = (
            -0.5
            * RHO_W
            * D
            * D
            * (C_N * np.linalg.norm(normal) * normal + C_T * math.pi * abs(along) * along * t)
        )
        return [force[0], force[2] - weight]

    expected = fsolve(balance, [0.05, -0.1], xtol=1e-14)
    assert expected[0] > 0.01  # it glides towards its low end (+x), not straight down
    v = fall(t, duration=6.0)
    np.testing.assert_allclose(v[:, 0], expected[0], rtol=1e-5)
    np.testing.assert_allclose(v[:, 2], expected[1], rtol=1e-5)
    np.testing.assert_allclose(v[:, 1], 0.0, atol=1e-9)


@pytest.mark.parametrize("law", ["sphere", "slender"])
def test_the_recorded_drag_impulse_is_all_the_water_gave_a_free_chain(law: str) -> None:
    """Two-way coupling gives the water minus the drag impulse the kernel records (issue 26,
    Eq. S2). A detached chain's bending and length constraints are internal, so its momentum
    changes by the buoyant weight and that impulse alone: sum m (v_end - v_start) =
    steps dt W + sum J, to round-off, in a current across it and while it bends."""
    particles, dt, steps = 12, 2e-3, 300
    model = build_chain_model(
        particles, D, 1e4, RHO_T, root="free", drag=law, normal_drag=C_N, tangential_drag=C_T
    )
    medium = Medium(RHO_W, MU, np.array([0.0, 0.0, -G]), RHO_T)
    rng = np.random.default_rng(5)
    bend = np.cumsum(np.column_stack([np.cos(np.linspace(0, 2, particles)),
                                      np.zeros(particles), np.sin(np.linspace(0, 2, particles))]),
                     axis=0) * D  # fmt: skip
    x = bend[None].copy()
    v = rng.standard_normal(x.shape) * 0.01
    v0 = v.copy()
    zeros = np.zeros((steps, 1, 3))
    flow = np.broadcast_to(np.array([0.1, 0.05, 0.0]), (steps, 1, particles, 3)).copy()
    impulse = np.zeros((1, particles, 3))
    diagnostics = np.zeros((1, 3))
    advance_frame(
        x, v, zeros, zeros, zeros + np.array([0.0, 0.0, -1.0]), zeros, np.zeros_like(x), flow,
        model, medium, dt, diagnostics, impulse, no_obstacle(),
    )  # fmt: skip
    assert diagnostics[0, 2] == -1
    weight = (RHO_T - RHO_W) * model.volume * G  # buoyant weight per particle, downwards
    change = (model.mass[:, None] * (v[0] - v0[0])).sum(axis=0)
    expected = impulse[0].sum(axis=0) + steps * dt * np.array([0.0, 0.0, -weight.sum()])
    np.testing.assert_allclose(change, expected, rtol=0, atol=1e-9 * np.abs(change).max())
    assert np.abs(impulse).max() > 0.1 * np.abs(change).max()  # the drag did real work
