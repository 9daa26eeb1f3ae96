"""The simulated water's velocity at a point (issue 26; docs/theory/soft-bell.md §8, Eq. S1):
the MPS weighted mean w(r) = r_e / r - 1 of the particles around it (Koshizuka & Oka 1996),
faded to still water where the water is thin."""

from __future__ import annotations

import numpy as np
import pytest

from jellysim.coupling.water_at import THIN, spread_reaction, water_velocity_at
from jellysim.fluid.mps import lattice_reference

L0, RE = 0.1, 2.1 * 0.1
N0 = lattice_reference(3, L0, 2.1).n0


def cube(n: int) -> np.ndarray:
    """Particles on the cubic lattice, n^3 of them, from the origin."""
    axis = np.arange(n) * L0
    return np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)


def test_inside_the_water_a_linear_field_is_sampled_exactly_at_symmetric_points() -> None:
    """At a lattice site and at a cell centre the neighbours are symmetric, so the weighted mean
    of a linear field is its value there (and of a uniform one, the uniform value anywhere)."""
    particles = cube(12)
    gradient = np.array([[0.3, -1.0, 0.5], [2.0, 0.1, 0.0], [0.0, 0.7, -0.4]])
    velocities = particles @ gradient.T + np.array([0.01, 0.02, 0.03])
    points = np.array([[5 * L0, 6 * L0, 5 * L0], [5.5 * L0, 5.5 * L0, 6.5 * L0]])
    sampled = water_velocity_at(points, particles, velocities, RE, N0)
    np.testing.assert_allclose(sampled, points @ gradient.T + [0.01, 0.02, 0.03], atol=1e-12)
    uniform = np.tile([0.2, -0.1, 0.05], (len(particles), 1))
    anywhere = np.array([[0.53, 0.61, 0.47]])
    np.testing.assert_allclose(
        water_velocity_at(anywhere, particles, uniform, RE, N0), [[0.2, -0.1, 0.05]], atol=1e-14
    )


def test_thin_water_fades_to_still_and_no_water_is_still() -> None:
    particles = cube(12)
    uniform = np.tile([0.0, 0.0, 1.0], (len(particles), 1))
    top = 11 * L0
    points = np.array(
        [
            [0.55, 0.55, top - 0.5 * L0],  # under the surface: full water around it
            [0.55, 0.55, top + 1.0 * L0],  # a layer above the surface: thin water
            [0.55, 0.55, top + 3.0 * L0],  # beyond r_e: no water
        ]
    )
    sampled = water_velocity_at(points, particles, uniform, RE, N0)
    speeds = sampled[:, 2]
    weights = RE / np.linalg.norm(particles[None] - points[:, None], axis=2) - 1.0
    density = np.where(weights > 0, weights, 0).sum(axis=1)
    assert density[0] >= THIN * N0 and speeds[0] == 1.0
    assert 0 < density[1] < THIN * N0
    assert speeds[1] == pytest.approx(density[1] / (THIN * N0), rel=1e-14)  # faded in proportion
    assert speeds[2] == 0.0 and not np.any(sampled[2])


def test_a_point_on_a_particle_takes_its_velocity() -> None:
    particles = cube(6)
    velocities = np.random.default_rng(3).standard_normal(particles.shape)
    sampled = water_velocity_at(particles[[40, 77]], particles, velocities, RE, N0)
    # its weight, ~1e9, outweighs its neighbours' (of order 1) by as much
    np.testing.assert_allclose(sampled, velocities[[40, 77]], atol=1e-7)


def test_the_reaction_gives_the_water_exactly_what_the_tentacles_took() -> None:
    """Eq. (S2): the momentum shared among the particles sums to minus the impulses of the
    points that have water within r_e; a point out of the water gives nothing."""
    particles = cube(10)
    rng = np.random.default_rng(7)
    points = np.vstack([rng.uniform(0.2, 0.7, (25, 3)), [[5.0, 5.0, 5.0]]])  # the last: no water
    impulses = rng.standard_normal((26, 3)) * 1e-3
    momentum = spread_reaction(points, impulses, particles, RE)
    np.testing.assert_allclose(momentum.sum(axis=0), -impulses[:-1].sum(axis=0), atol=1e-17)
    # Each point's share goes to the particles within r_e of it, most to the nearest.
    one = spread_reaction(points[:1], impulses[:1], particles, RE)
    distance = np.linalg.norm(particles - points[0], axis=1)
    assert np.all(one[distance >= RE] == 0.0)
    nearest = np.argmin(distance)
    assert np.all(np.abs(one[nearest]) == np.abs(one).max(axis=0))
