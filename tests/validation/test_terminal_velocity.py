"""A detached chain falling along its axis reaches the drag law's terminal velocity.

At terminal speed U the buoyant weight of the chain, (P - 1) segments of volume pi d^3 / 4,
balances the sphere drag on its P particles (paper Eq. 3-5): ``(P-1) (rho_t - rho_w) V g =
P F(U)``. In the Stokes range F = 3 pi mu d U gives U in closed form.
"""

import math

import numpy as np
import pytest
from hanging import hang
from scipy.optimize import brentq

from jellysim.tentacle.kernels import Medium, drag_gain
from jellysim.tentacle.model import build_chain_model

DOWN = np.array([0.0, 0.0, -1.0])


def fall(particles, spacing, rho_t, rho_w, mu, duration, dt):
    model = build_chain_model(particles, spacing, 1e4, rho_t, root="free")
    medium = Medium(rho_w, mu, np.array([0.0, 0.0, -9.81]), rho_t)
    x = (np.arange(particles)[:, None] * spacing * DOWN)[None].copy()
    v = np.zeros_like(x)
    steps = round(duration / dt)
    diagnostics = hang(x, v, model, medium, steps, dt)
    assert diagnostics[0, 2] == -1
    return v[0]


def weight_balance(particles, spacing, rho_t, rho_w):
    return (particles - 1) * (rho_t - rho_w) * math.pi * spacing**3 / 4 * 9.81 / particles


def test_terminal_velocity_in_the_newton_range():
    particles, d, rho_t, rho_w, mu = 10, 0.01, 1100.0, 1000.0, 1e-3
    load = weight_balance(particles, d, rho_t, rho_w)
    speed = brentq(lambda u: drag_gain(u, d, rho_w, mu) * u - load, 1e-6, 10.0)
    assert 1.0 < speed * d * rho_w / mu < 1e4  # the (0.55 + 4.8 / sqrt(Re))^2 branch
    v = fall(particles, d, rho_t, rho_w, mu, duration=3.0, dt=2e-3)
    np.testing.assert_allclose(v[:, 2], -speed, rtol=0.01)
    np.testing.assert_allclose(v[:, :2], 0.0, atol=1e-9)


def test_terminal_velocity_in_the_stokes_range():
    particles, d, rho_t, rho_w, mu = 8, 1e-4, 1500.0, 1000.0, 1e-3
    speed = weight_balance(particles, d, rho_t, rho_w) / (3 * math.pi * mu * d)
    assert speed * d * rho_w / mu < 1.0
    v = fall(particles, d, rho_t, rho_w, mu, duration=0.05, dt=1e-4)
    np.testing.assert_allclose(v[:, 2], -speed, rtol=1e-6)


@pytest.mark.parametrize("dt", [1e-3, 4e-3])
def test_fall_speed_grows_monotonically_to_terminal(dt):
    particles, d = 10, 0.01
    model_speeds = [
        -fall(particles, d, 1100.0, 1000.0, 1e-3, t, dt)[:, 2].mean() for t in (0.1, 0.4, 1.6)
    ]
    assert model_speeds[0] < model_speeds[1] < model_speeds[2]
