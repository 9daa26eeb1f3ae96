"""The lists cut to the near radius (fluid.neighbours.near_neighbours): every entry of the whole
list within the radius, in its order, so that the kernels of the number-density and gradient
radius give the same numbers, bit for bit, from either list (docs/performance.md, "Lists at the
near radius")."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from jellysim.fluid import kernels, neighbours
from jellysim.fluid.geometry import DUMMY, FLUID, WALL, water_block
from jellysim.fluid.mps import MPSParameters, MPSSolver

L0 = 0.01


def _jittered_solver(dim: int, seed: int = 7) -> MPSSolver:
    """A block of particles off their lattice (0.15 l0 of noise: the order of the near and far
    entries in each row is irregular, as in a running flow), the lowest rows walls and dummies,
    with random velocities and pressures and a few particles dead."""
    rng = np.random.default_rng(seed)
    if dim == 2:
        positions = water_block(0.0, 0.16, 0.0, 0.12, L0)
    else:
        positions = water_block(0.0, 0.08, 0.0, 0.08, L0, 0.0, 0.07)
    positions = positions + rng.normal(scale=0.15 * L0, size=positions.shape)
    up = positions[:, -1]
    kinds = np.full(len(positions), FLUID, dtype=np.int8)
    kinds[up < 2.5 * L0] = WALL
    kinds[up < 1.5 * L0] = DUMMY
    solver = MPSSolver(MPSParameters(dim=dim, l0=L0, re_laplacian=3.1), positions, kinds)
    solver.velocity[:] = rng.normal(scale=0.05, size=positions.shape) * (kinds == FLUID)[:, None]
    solver.pressure[:] = rng.uniform(0.0, 500.0, size=len(positions)) * (kinds != DUMMY)
    solver.alive[rng.choice(np.flatnonzero(kinds == FLUID), size=5, replace=False)] = False
    return solver


@pytest.mark.parametrize("dim", [2, 3])
def test_near_list_is_the_whole_list_cut_to_the_radius_in_its_order(dim) -> None:
    solver = _jittered_solver(dim)
    rows = solver.alive & (solver.kind != DUMMY)
    whole = solver.neighbours(rows)
    radius = solver.near_radius
    assert radius < whole.radius
    tiny = [np.empty(3, dtype=np.int32), np.empty(3)]
    start, index, distance = neighbours.near_neighbours(whole, radius, *tiny)
    assert index is not tiny[0]  # outgrown: new arrays
    kept = 0
    for i in range(len(rows)):
        row = slice(whole.start[i], whole.start[i + 1])
        near = whole.distance[row] < radius
        assert np.array_equal(index[start[i] : start[i + 1]], whole.indices[row][near])
        assert np.array_equal(distance[start[i] : start[i + 1]], whole.distance[row][near])
        kept += int(near.sum())
    assert start[-1] == kept and 0 < kept < whole.start[-1]
    # into buffers that hold it: the same list in the same arrays
    again = neighbours.near_neighbours(whole, radius, index, distance)
    assert again[1] is index and again[2] is distance
    assert np.array_equal(again[0], start)
    # the solver's own, and a list no wider than the radius is its own near list
    cut = solver.near(whole)
    assert cut.radius == radius and np.array_equal(cut.indices, index[: start[-1]])
    assert solver.near(cut) is cut


@pytest.mark.parametrize("dim", [2, 3])
def test_kernels_of_the_near_radius_give_the_same_bits_from_either_list(dim) -> None:
    solver = _jittered_solver(dim)
    c = solver.constants
    whole = solver.neighbours(solver.alive & (solver.kind != DUMMY))
    near = solver.near(whole)
    n = len(solver.kind)
    args = (solver.position, solver.velocity)

    def both(run):
        return [run(nb) for nb in (whole, near)]

    def density(nb):
        out, count = np.empty(n), np.empty(n, dtype=np.int64)
        kernels.number_density(nb, solver.alive, c.re_number_density, out, count)
        return out, count

    def divergence(nb):
        out = np.empty(n)
        kernels.velocity_divergence(*args, solver.kind, solver.alive, nb, c, out)
        return (out,)

    surface = solver.alive & (solver.kind == FLUID) & (solver.position[:, -1] > 0.05)

    def correction(nb, corrected=True, repulsion=False, conservative=False):
        x, u = np.empty_like(solver.position), np.empty_like(solver.velocity)
        common = (*args, solver.pressure, solver.kind, solver.alive, nb, c, 1e-3, x, u)
        if conservative:
            kernels.conservative_pressure_correction(*common)
        elif repulsion:  # Eq. (F10b)'s normal reads the whole list
            kernels.pressure_correction(*common, corrected, surface, whole)
        else:
            kernels.pressure_correction(*common, corrected)
        return x, u

    def collision(nb):
        x, u = np.empty_like(solver.position), np.empty_like(solver.velocity)
        kernels.collision(*args, solver.kind, solver.alive, nb, 0.8 * L0, 0.2, 1e-3, x, u)
        return x, u

    checks = {
        "number density": both(density),
        "divergence": both(divergence),
        "gradient": both(lambda nb: correction(nb, corrected=False)),
        "corrected gradient": both(correction),
        "with surface repulsion": both(lambda nb: correction(nb, repulsion=True)),
        "conservative gradient": both(lambda nb: correction(nb, conservative=True)),
        "collisions": both(collision),
    }
    for name, (from_whole, from_near) in checks.items():
        for a, b in zip(from_whole, from_near, strict=True):
            assert np.array_equal(a, b), name
    moved = checks["collisions"][0][1] != solver.velocity
    assert moved.any(), "some pairs collide"
    assert np.any(checks["corrected gradient"][0][1] != solver.velocity)


@pytest.mark.parametrize("dim", [2, 3])
def test_verlet_cut_makes_the_whole_and_the_near_list_in_the_same_passes(dim) -> None:
    """With a skin, the list at the search radius and its near list are cut together from the
    Verlet list (neighbours.filter_with_near): the first holds the pairs of a fresh search, at
    the same distances to the last bit, in the candidates' order; the second is the first cut
    to the near radius (neighbours.near_neighbours), entry for entry."""
    solver = _jittered_solver(dim)
    skin = 0.4
    solver = MPSSolver(
        dataclasses.replace(solver.params, neighbour_skin=skin), solver.position, solver.kind
    )
    rows = solver.kind != DUMMY
    solver.neighbours_and_near(rows, "start", "near")  # builds the Verlet list
    candidates = solver._candidates
    assert candidates is not None and solver.searches == 1
    rng = np.random.default_rng(3)
    step = rng.normal(size=solver.position.shape)
    step *= 0.45 * skin * L0 / np.linalg.norm(step, axis=1, keepdims=True)
    solver.position += step * (solver.kind == FLUID)[:, None]
    solver.alive[rng.choice(np.flatnonzero(solver.kind == FLUID), size=4, replace=False)] = False
    whole, near = solver.neighbours_and_near(rows & solver.alive, "start", "near")
    assert solver.searches == 1  # cut from the same Verlet list
    fresh = neighbours.neighbour_list(
        solver.position, solver.alive, rows & solver.alive, solver.search_radius
    )
    assert np.array_equal(whole.start, fresh[0])
    for i in range(len(rows)):
        row = slice(whole.start[i], whole.start[i + 1])
        got = dict(zip(whole.indices[row].tolist(), whole.distance[row].tolist(), strict=True))
        want = dict(zip(fresh[1][row].tolist(), fresh[2][row].tolist(), strict=True))
        assert got == want
        order = list(candidates.indices[candidates.start[i] : candidates.start[i + 1]])
        places = [order.index(j) for j in whole.indices[row]]
        assert places == sorted(places)
    tiny = [np.empty(3, dtype=np.int32), np.empty(3)]
    cut = neighbours.near_neighbours(whole, solver.near_radius, *tiny)
    assert 0 < cut[0][-1] < whole.start[-1]
    assert np.array_equal(near.start, cut[0])
    assert np.array_equal(near.indices, cut[1][: cut[0][-1]])
    assert np.array_equal(near.distance, cut[2][: cut[0][-1]])
    # the plain cut (filter_neighbours, neighbours) is the same whole list
    plain = solver.neighbours(rows & solver.alive)
    for a, b in zip(plain[:3], whole[:3], strict=True):
        assert np.array_equal(a, b)
    # the scratch is kept: a float for every candidate
    assert solver._filter_scratch.size >= candidates.indices.size
