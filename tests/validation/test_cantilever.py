"""Clamped cantilever under a uniform load against Euler-Bernoulli (docs/theory/tentacle.md §4).

Closed form: tip deflection ``w L^4 / (8 EI)`` for a beam of length L clamped at one end under a
uniform load w per length (Timoshenko & Gere, Mechanics of Materials, Table G-1, case 1).
The chain is clamped at its root particle (mirror ghost, DESIGN §2) and its load is lumped as
its mass: a whole segment on each interior particle, half on the tip.
"""

import math

import numpy as np
import pytest
from hanging import hang

from jellysim.tentacle.kernels import Medium
from jellysim.tentacle.model import build_chain_model, second_moment

DOWN = np.array([0.0, 0.0, -1.0])


def static_tip_deflection(bending, particles=60, spacing=0.01, modulus=5e9, load_g=9.81):
    """Settle a chain hanging along -z under a sideways (x) body load; tip x in m."""
    rho_w, rho_t = 1000.0, 2000.0
    model = build_chain_model(particles, spacing, modulus, rho_t, bending, "clamped")
    medium = Medium(rho_w, 1e-3, np.array([load_g, 0.0, 0.0]), rho_t)
    x = (np.arange(particles)[:, None] * spacing * DOWN)[None].copy()
    v = np.zeros_like(x)
    # Backward Euler with a long step converges to the static equilibrium.
    steps = 100
    diagnostics = hang(x, v, model, medium, steps, 20.0)
    assert diagnostics[0, 2] == -1
    assert np.abs(v).max() < 1e-9, "not settled"
    length = (particles - 1) * spacing
    w = (rho_t - rho_w) * math.pi * spacing**2 / 4 * load_g
    return x[0, -1, 0], w * length**4 / (8 * modulus * second_moment(spacing))


def test_cantilever_within_3_percent_of_euler_bernoulli_at_60_particles():
    tip, theory = static_tip_deflection("euler-bernoulli")
    assert 1e-4 < tip / 0.59 < 1e-2  # small deflection: the linear theory applies
    assert tip == pytest.approx(theory, rel=0.03)
    # In fact the discretisation error is far smaller (0.03 % at 60 particles, ~1/P^2).
    assert tip == pytest.approx(theory, rel=2e-3)


def test_ewing_span_is_exactly_one_and_a_half_times_stiffer():
    eb, _ = static_tip_deflection("euler-bernoulli")
    ewing, _ = static_tip_deflection("ewing")
    assert eb / ewing == pytest.approx(1.5, rel=1e-3)


def test_discretisation_error_falls_with_resolution():
    errors = []
    for particles in (15, 30, 60):
        spacing = 0.59 / (particles - 1)
        tip, theory = static_tip_deflection("euler-bernoulli", particles, spacing, modulus=5e9)
        errors.append(abs(tip / theory - 1))
    assert errors[0] > errors[1] > errors[2]


def test_pinned_root_carries_no_moment():
    # A pinned root is a free hinge: under a sideways load the chain swings until it lies along
    # the load, straight (no bending at equilibrium), however stiff it is.
    particles, spacing = 30, 0.01
    model = build_chain_model(particles, spacing, 5e9, 2000.0, "euler-bernoulli", "pinned")
    # Syrup (1 Pa s) damps the pendulum so that it settles.
    medium = Medium(1000.0, 1.0, np.array([9.81, 0.0, 0.0]), 2000.0)
    x = (np.arange(particles)[:, None] * spacing * DOWN)[None].copy()
    v = np.zeros_like(x)
    diagnostics = hang(x, v, model, medium, 1200, 0.05)
    assert diagnostics[0, 2] == -1
    expected = np.arange(particles) * spacing
    np.testing.assert_allclose(x[0, :, 0], expected, atol=1e-6)
    np.testing.assert_allclose(x[0, :, 1:], 0.0, atol=1e-6)
