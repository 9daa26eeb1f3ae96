"""Tentacle kernels against closed forms and invariants (paper §4.1; docs/theory/tentacle.md)."""

import math

import numpy as np
import pytest
from hanging import hang
from saddle import saddle_system

from jellysim.tentacle.kernels import (
    KKT_PADDING,
    Medium,
    _band_ldlt_solve,
    bending_energy,
    bending_forces,
    project_lengths,
)
from jellysim.tentacle.model import (
    SPAN_CUBED,
    bending_bands,
    bending_stiffness,
    build_chain_model,
    effective_bending_rigidity,
    second_moment,
)

DOWN = np.array([0.0, 0.0, -1.0])


def random_chain(rng, particles=12, spacing=0.01):
    steps = DOWN * spacing + rng.normal(scale=0.3 * spacing, size=(particles - 1, 3))
    return np.vstack([np.zeros(3), np.cumsum(steps, axis=0)])


@pytest.mark.parametrize("clamped", [True, False])
def test_bending_force_is_minus_gradient_of_energy(clamped):
    rng = np.random.default_rng(3)
    x = random_chain(rng)
    c = 7.3
    forces = np.empty_like(x)
    bending_forces(x, c, clamped, DOWN, forces)
    h = 1e-6
    for i in range(x.shape[0]):
        for k in range(3):
            plus, minus = x.copy(), x.copy()
            plus[i, k] += h
            minus[i, k] -= h
            grad = bending_energy(plus, c, clamped, DOWN) - bending_energy(minus, c, clamped, DOWN)
            assert forces[i, k] == pytest.approx(-grad / (2 * h), abs=1e-8)


def test_bending_force_is_the_papers_three_point_rule():
    # Paper Eq. 1-2: h_i = x_i - (x_{i-1} + x_{i+1}) / 2, P = c h: -P on i, +P/2 on i-1 and i+1.
    x = np.zeros((3, 3))
    x[:, 2] = [0.0, -1.0, -2.0]
    x[1, 0] = 0.25  # the middle particle displaced sideways by h = 0.25
    forces = np.empty_like(x)
    bending_forces(x, 2.0, False, DOWN, forces)
    np.testing.assert_allclose(forces[:, 0], [0.25, -0.5, 0.25], rtol=1e-15)
    np.testing.assert_allclose(forces[:, 1:], 0.0, atol=1e-15)


@pytest.mark.parametrize("clamped", [True, False])
def test_internal_forces_sum_to_zero(clamped):
    x = random_chain(np.random.default_rng(5))
    forces = np.empty_like(x)
    bending_forces(x, 11.0, clamped, DOWN, forces)
    np.testing.assert_allclose(forces.sum(axis=0), 0.0, atol=1e-12)


def dense_bending_matrix(particles, clamped):
    """The slow oracle: K (P, P) summed stencil by stencil, Eq. (T3)."""
    k = np.zeros((particles, particles))
    stencil = np.array([1.0, -2.0, 1.0])
    for i in range(1, particles - 1):
        k[i - 1 : i + 2, i - 1 : i + 2] += 0.25 * np.outer(stencil, stencil)
    if clamped:
        k[0:2, 0:2] += 0.5 * np.array([[1.0, -1.0], [-1.0, 1.0]])
    return k


def from_bands(particles, clamped):
    diagonal, first, second = bending_bands(particles, clamped)
    return (
        np.diag(diagonal)
        + np.diag(first, 1)
        + np.diag(first, -1)
        + np.diag(second, 2)
        + np.diag(second, -2)
    )


@pytest.mark.parametrize("particles", [3, 4, 5, 12, 60])
@pytest.mark.parametrize("clamped", [True, False])
def test_bending_bands_are_the_dense_matrix_exactly(particles, clamped):
    np.testing.assert_array_equal(
        from_bands(particles, clamped), dense_bending_matrix(particles, clamped)
    )


def test_the_largest_chain_allocates_no_square_matrix():
    """tentacles.particles = 100,000 (the documented maximum): a dense K would take 75 GiB
    (issue 24); the bands and the model take O(P)."""
    import tracemalloc

    tracemalloc.start()
    model = build_chain_model(100_000, 0.001, 1e5, 1000.0)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert model.stiffness_diag.shape == (99_999,)
    assert peak < 50 * 2**20  # bytes: a few arrays of 100,000 floats


def test_bending_matrix_matches_the_force():
    rng = np.random.default_rng(9)
    x = random_chain(rng)
    for clamped in (True, False):
        k = from_bands(x.shape[0], clamped)
        assert np.allclose(k, k.T)
        forces = np.empty_like(x)
        bending_forces(x, 1.0, clamped, DOWN, forces)
        linear = -k @ x
        if clamped:  # the clamp's rank-one part along t is kept out of K
            e = x[1] - x[0]
            linear[1] += 0.5 * (e @ DOWN) * DOWN
            linear[0] -= 0.5 * (e @ DOWN) * DOWN
        np.testing.assert_allclose(forces, linear, atol=1e-14)


def test_bending_coefficients_as_data():
    # c = 48 E I / L^3 with I = pi d^4 / 64 (paper Eq. 1-2); continuum EI_eff = c d^3 / 4.
    e_modulus, d = 2.4e5, 0.01
    assert second_moment(d) == pytest.approx(math.pi * d**4 / 64, rel=1e-15)
    assert SPAN_CUBED == {"euler-bernoulli": 12.0, "ewing": 8.0}
    ei = e_modulus * second_moment(d)
    assert effective_bending_rigidity(e_modulus, d, "euler-bernoulli") == pytest.approx(
        ei, rel=1e-14
    )
    assert effective_bending_rigidity(e_modulus, d, "ewing") == pytest.approx(1.5 * ei, rel=1e-14)
    assert bending_stiffness(e_modulus, d, "ewing") == pytest.approx(
        48 * ei / (2 * d) ** 3, rel=1e-14
    )


def test_lumped_masses():
    model = build_chain_model(10, 0.02, 1e3, 1050.0)
    segment = 1050.0 * math.pi * 0.02**3 / 4
    np.testing.assert_allclose(model.mass[1:-1], segment, rtol=1e-15)
    assert model.mass[-1] == pytest.approx(segment / 2, rel=1e-15)
    assert model.inverse_mass[0] == 0.0  # prescribed root
    free = build_chain_model(10, 0.02, 1e3, 1050.0, root="free")
    assert free.mass.sum() == pytest.approx(9 * segment, rel=1e-14)


@pytest.mark.parametrize("n", [24, 48])
def test_banded_ldlt_solve_equals_dense_solve_on_a_saddle_point_system(n):
    # SPD block over 3 unknowns per particle, one multiplier after each particle (as assembled),
    # stored between KKT_PADDING zero rows before and after.
    a, band, x = saddle_system(np.random.default_rng(1), n)
    rhs = x[KKT_PADDING : KKT_PADDING + n].copy()
    _band_ldlt_solve(band, np.empty(n + 2 * KKT_PADDING), x)
    np.testing.assert_allclose(
        x[KKT_PADDING : KKT_PADDING + n], np.linalg.solve(a, rhs), rtol=1e-10, atol=1e-12
    )
    assert not np.any(x[:KKT_PADDING]) and not np.any(x[KKT_PADDING + n :])


def test_projection_restores_lengths_and_keeps_the_root():
    rng = np.random.default_rng(2)
    d = 0.01
    x = random_chain(rng, 40, d)
    x += rng.normal(scale=0.05 * d, size=x.shape)
    x[0] = 0.0
    model = build_chain_model(40, d, 1e3, 1000.0)
    iterations = project_lengths(
        x, model.inverse_mass, d, 1e-12, 50, np.empty((39, 3)), np.empty((4, 39))
    )
    assert 0 < iterations <= 8
    lengths = np.linalg.norm(np.diff(x, axis=0), axis=1)
    np.testing.assert_allclose(lengths, d, rtol=1e-12)
    np.testing.assert_array_equal(x[0], 0.0)


def test_projection_conserves_momentum_of_a_free_chain():
    rng = np.random.default_rng(4)
    d = 0.01
    x = random_chain(rng, 30, d) + rng.normal(scale=0.1 * d, size=(30, 3))
    model = build_chain_model(30, d, 1e3, 1000.0, root="free")
    before = model.mass @ x
    project_lengths(x, model.inverse_mass, d, 1e-12, 50, np.empty((29, 3)), np.empty((4, 29)))
    np.testing.assert_allclose(model.mass @ x, before, rtol=0, atol=1e-15)


def test_integrator_conserves_momentum_of_a_free_chain():
    # No gravity, (almost) no water: only bending and the length constraints act, and both are
    # internal, so the total momentum stays put through the implicit step and the projection.
    rng = np.random.default_rng(6)
    d, particles, steps = 0.01, 25, 200
    model = build_chain_model(particles, d, 2.4e5, 1000.0, root="free")
    medium = Medium(1e-12, 1e-15, np.zeros(3), 1000.0)
    x = random_chain(rng, particles, d)[None].copy()
    project_lengths(x[0], model.inverse_mass, d, 1e-12, 50, np.empty((24, 3)), np.empty((4, 24)))
    v = rng.normal(scale=0.1, size=x.shape)
    momentum = model.mass @ v[0]
    diagnostics = hang(x, v, model, medium, steps, 1e-3)
    assert diagnostics[0, 2] == -1
    np.testing.assert_allclose(model.mass @ v[0], momentum, rtol=1e-9, atol=1e-15)
    assert np.linalg.norm(v[0] - v[0].mean(axis=0)) > 1e-3  # it did move and bend


def test_chain_health_is_the_rms_speed_and_finiteness_of_each_chain():
    from jellysim.tentacle.kernels import chain_health

    rng = np.random.default_rng(8)
    x = rng.normal(size=(5, 7, 3))
    v = rng.normal(size=(5, 7, 3))
    x[1, 3, 2] = np.nan  # a position not finite
    v[2, 6, 0] = np.inf  # a velocity not finite
    v[3, 0, 1] = np.nan
    rms, finite = chain_health(x, v)
    expected = np.sqrt(np.mean(np.sum(v**2, axis=2), axis=1))
    np.testing.assert_allclose(rms[[0, 1, 4]], expected[[0, 1, 4]], rtol=1e-14)
    np.testing.assert_array_equal(finite, [True, False, False, False, True])
