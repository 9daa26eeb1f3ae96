"""The pressure Poisson equation and its solvers on a dam-break configuration; checkpoints."""

from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from jellysim.errors import SimulationUnstable
from jellysim.fluid import deflation, linalg, mps, solvers
from jellysim.fluid.geometry import DUMMY, FLUID, tank, water_block
from jellysim.fluid.mps import MPSParameters, MPSSolver
from jellysim.fluid.solvers import FluidDiverged, solve

A = 0.1  # column width, m
L0 = A / 20


def dam_break(**overrides: object) -> MPSSolver:
    walls, wall_kinds = tank(5 * A, 2.5 * A, L0)
    fluid = water_block(0, A, 0, 2 * A, L0)
    positions = np.vstack([fluid, walls])
    kinds = np.concatenate([np.full(len(fluid), FLUID, dtype=np.int8), wall_kinds])
    return MPSSolver(MPSParameters(dim=2, l0=L0, **overrides), positions, kinds)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def released() -> tuple[linalg.Matrix, np.ndarray, solvers.CoarseSpace]:
    """The PPE of a dam break 20 steps after release (matrix, right-hand side and the rows'
    positions for the deflated solver's aggregates of 4 l0)."""
    solver = dam_break()
    dt = 5e-4
    for _ in range(20):
        solver.step(dt)
    built = solver.poisson_system(dt)
    coarse = solvers.CoarseSpace(solver.position[built.particles], solver.domain_min, 4 * L0)
    return built.matrix, built.rhs, coarse


@pytest.fixture(scope="module")
def system(released) -> tuple[linalg.Matrix, np.ndarray]:
    """The PPE of :func:`released` (matrix and right-hand side)."""
    return released[0], released[1]


def to_scipy(matrix: linalg.Matrix) -> sp.csr_matrix:
    n = matrix.indptr.shape[0] - 1
    return sp.csr_matrix((matrix.data, matrix.indices, matrix.indptr), shape=(n, n))


def test_poisson_matrix_is_symmetric_and_diagonally_dominant(system) -> None:
    matrix, rhs = system
    a = to_scipy(matrix)
    assert a.shape[0] > 500 and np.any(rhs != 0)
    assert abs(a - a.T).max() <= 1e-12 * abs(a).max()
    diagonal = a.diagonal()
    off = np.asarray(abs(a).sum(axis=1)).ravel() - np.abs(diagonal)
    assert np.all(diagonal > 0)
    assert np.all(diagonal >= off * (1 - 1e-12))  # weakly diagonally dominant
    assert np.any(diagonal > off * 1.01)  # strictly in rows next to the free surface
    assert np.all(a.data[a.indices != np.repeat(np.arange(a.shape[0]), np.diff(a.indptr))] < 0)


@pytest.mark.parametrize("method", ["iccg", "cg", "deflated"])
def test_solution_equals_direct_solve(released, method: str) -> None:
    matrix, rhs, coarse = released
    direct = spla.spsolve(to_scipy(matrix).tocsc(), rhs)
    x = np.zeros_like(rhs)
    iterations, residual, shift = solve(matrix, rhs, x, method, 1e-10, 5000, coarse)
    assert residual <= 1e-10 and shift == 0.0 and iterations > 0
    np.testing.assert_allclose(x, direct, rtol=0, atol=1e-7 * np.abs(direct).max())


def test_iccg_needs_three_times_fewer_iterations_than_cg(system) -> None:
    matrix, rhs = system
    counts = {}
    for method in ("iccg", "cg"):
        x = np.zeros_like(rhs)
        counts[method], residual, _ = solve(matrix, rhs, x, method, 1e-8, 5000)
        assert residual <= 1e-8
    print(f"PPE n = {rhs.size}: ICCG {counts['iccg']} iterations, CG {counts['cg']}")
    assert counts["iccg"] * 3 <= counts["cg"]


def test_deflated_cg_needs_far_fewer_iterations_than_cg(released) -> None:
    """Issue 5's 3x: the coarse problem removes the smooth modes that CG and ICCG spend their
    iterations on. Here (20 across, ~600 rows) 55 CG, 17 ICCG, 14 deflated; the gap widens
    with the size (57,800 rows of the 2-D dam break: 409, 105, 15; docs/performance.md)."""
    matrix, rhs, coarse = released
    counts = {}
    for method in ("deflated", "iccg", "cg"):
        x = np.zeros_like(rhs)
        counts[method], residual, _ = solve(matrix, rhs, x, method, 1e-8, 5000, coarse)
        assert residual <= 1e-8
        assert np.linalg.norm(rhs - to_scipy(matrix) @ x) <= 1e-8 * np.linalg.norm(rhs) * 1.01
    print(f"PPE n = {rhs.size}: iterations {counts}")
    assert counts["deflated"] * 3 <= counts["cg"]
    assert counts["deflated"] < counts["iccg"]


def test_a_singular_coarse_problem_is_a_diagnosed_divergence(released, monkeypatch) -> None:
    """SuperLU's error on a singular E (A not definite) becomes the run's FluidDiverged (exit
    status 3 with a diagnosis), not a traceback."""
    matrix, rhs, coarse = released

    def singular(*args: object, **kwargs: object) -> None:
        raise RuntimeError("Factor is exactly singular")

    monkeypatch.setattr(spla, "splu", singular)
    with pytest.raises(FluidDiverged, match="coarse problem could not be factored"):
        solve(matrix, rhs, np.zeros_like(rhs), "deflated", 1e-8, 100, coarse)


def test_coarse_operator_is_z_transpose_a_z(released) -> None:
    """The compiled W = Z^T A and E = Z^T A Z equal products of sparse matrices (slow
    reference); every
    row lies in one aggregate, each aggregate holds a row, and the cells are 4 l0 wide."""
    matrix, _, coarse = released
    key, m = deflation.aggregates(coarse.position, coarse.origin, coarse.size)
    n = key.size
    assert np.array_equal(np.unique(key), np.arange(m))
    for a in range(m):
        members = coarse.position[key == a]
        assert np.all(np.ptp(members, axis=0) < coarse.size)
    z = sp.csr_matrix((np.ones(n), (np.arange(n), key)), shape=(n, m))
    restriction = deflation.restricted_operator(matrix, key, m)
    w = sp.csr_matrix((restriction.data, restriction.indices, restriction.indptr), shape=(m, n))
    w_reference = (z.T @ to_scipy(matrix)).toarray()
    np.testing.assert_allclose(w.toarray(), w_reference, rtol=1e-12, atol=0)
    reference = (z.T @ to_scipy(matrix) @ z).toarray()
    fast = deflation.coarse_operator(restriction, key, m)
    assert np.all(np.diff(fast.indptr) > 0)
    for a in range(m):
        row = fast.indices[fast.indptr[a] : fast.indptr[a + 1]]
        assert np.all(np.diff(row) > 0)  # sorted, no duplicates
    np.testing.assert_allclose(
        fast.toarray(), reference, rtol=1e-12, atol=1e-12 * abs(reference).max()
    )


def test_aggregates_and_members_are_numpys_sorts_without_sorting(monkeypatch) -> None:
    """The aggregates' numbering by one pass over the lattice box's cells is np.unique's
    inverse (rows scattered, empty cells between), as is the np.unique fallback for a box far
    larger than the rows (a far group); the members' counting sort is a stable argsort."""
    rng = np.random.default_rng(5)
    origin, size = np.array([-0.31, -0.31, -0.31]), 0.04
    compact = rng.uniform(-0.3, 0.5, (3000, 3))  # 20^3 cells, 3,000 rows: a pass over cells
    spread = compact.copy()
    spread[:40] += 7.0  # 195^3 cells: np.unique
    passes = []
    numbered = deflation._numbered_cells
    monkeypatch.setattr(
        deflation, "_numbered_cells", lambda *args: passes.append(1) or numbered(*args)
    )
    for position, dense in ((compact, True), (spread, False)):
        passes.clear()
        key, m = deflation.aggregates(position, origin, size)
        assert bool(passes) == dense
        cell = np.floor((position - origin) / size).astype(np.int64)
        cell -= cell.min(axis=0)
        linear = np.ravel_multi_index(tuple(cell.T), tuple(cell.max(axis=0) + 1))
        unique, inverse = np.unique(linear, return_inverse=True)
        np.testing.assert_array_equal(key, inverse.ravel())
        assert m == unique.size
        start, members = deflation._members(key, m)
        np.testing.assert_array_equal(members, np.argsort(key, kind="stable"))
        np.testing.assert_array_equal(np.diff(start), np.bincount(key, minlength=m))


@pytest.mark.parametrize("dim", [2, 3])
def test_aggregates_are_numpys_cells_below_the_origin_and_on_cell_edges(dim: int) -> None:
    """The compiled numbering against NumPy's floor, bounds and np.ravel_multi_index: rows below
    and above the lattice's origin, some exactly on cell edges (floor of a whole number), in 2-D
    and 3-D; a lone row is aggregate 0 of 1."""
    rng = np.random.default_rng(dim)
    size = 0.25
    origin = np.array([0.1, -0.3, 0.05][:dim])
    position = rng.uniform(-1.3, 0.9, (2000, dim))
    position[:300] = origin + size * rng.integers(-5, 4, (300, dim))  # on the edges
    key, m = deflation.aggregates(position, origin, size)
    cell = np.floor((position - origin) / size).astype(np.int64)
    assert cell.min() < 0 and np.any((position[:300] - origin) / size % 1.0 == 0.0)
    cell -= cell.min(axis=0)
    linear = np.ravel_multi_index(tuple(cell.T), tuple(cell.max(axis=0) + 1))
    unique, inverse = np.unique(linear, return_inverse=True)
    np.testing.assert_array_equal(key, inverse.ravel())
    assert m == unique.size
    lone = deflation.aggregates(position[:1], origin, size)
    assert lone[1] == 1 and lone[0].tolist() == [0]


def test_the_deflated_solvers_unsorted_matrix_is_the_same_matrix() -> None:
    """Assembled for the deflated solver the rows keep neighbour order (diagonal first); as a
    matrix it is the sorted one, entry for entry."""
    dt = 5e-4
    fluid = dam_break()
    for _ in range(5):
        fluid.step(dt)
    systems = [fluid.poisson_system(dt)]
    fluid.params = dataclasses.replace(fluid.params, solver="deflated")
    systems.append(fluid.poisson_system(dt))
    ordered, unordered = systems[0].matrix, systems[1].matrix
    np.testing.assert_array_equal(systems[0].particles, systems[1].particles)
    rows = np.arange(unordered.indptr.size - 1)
    assert np.array_equal(unordered.indices[unordered.diagonal], rows)
    assert np.array_equal(unordered.diagonal, unordered.indptr[:-1])
    assert abs(to_scipy(ordered) - to_scipy(unordered)).max() == 0.0
    np.testing.assert_array_equal(systems[0].rhs, systems[1].rhs)


@pytest.mark.parametrize("solver", ["iccg", "cg", "deflated"])
def test_a_single_precision_matrix_rounds_the_entries_and_keeps_each_rows_excess(
    solver: str,
) -> None:
    """fluid.matrix_precision = "single": the off-diagonal entries are the double matrix's
    rounded, entry for entry in the same pattern; the diagonal, in double, sums the rounded
    entries, so each row's excess over its unknown neighbours (the free-surface neighbours and
    the compressibility) is the double one to the round-off of the sums; the right-hand side is
    the same. Each solver solves that matrix to the tolerance asked."""
    dt = 5e-4
    fluid = dam_break(solver=solver)
    for _ in range(5):
        fluid.step(dt)
    double = fluid.poisson_system(dt)
    fluid.params = dataclasses.replace(fluid.params, matrix_precision="single")
    single = fluid.poisson_system(dt)
    a, b = double.matrix, single.matrix
    assert a.data.dtype == np.float64 and b.data.dtype == np.float32
    assert a.diagonal_value.size == 0 and b.diagonal_value.dtype == np.float64
    for name in ("indptr", "indices", "diagonal", "blocks"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    off = np.ones(a.data.size, dtype=bool)
    off[a.diagonal] = False
    np.testing.assert_array_equal(a.data[off].astype(np.float32), b.data[off])
    assert np.any(a.data[off] != b.data[off]) and np.all(b.data[b.diagonal] == 0.0)
    rows = np.repeat(np.arange(a.diagonal.size), np.diff(a.indptr))
    excess = [
        np.bincount(rows, weights=m.data.astype(np.float64), minlength=a.diagonal.size)
        + linalg.diagonal_values(m) * (m is b)
        for m in (a, b)
    ]
    scale = a.data[a.diagonal].max()
    np.testing.assert_allclose(excess[1], excess[0], rtol=0, atol=1e-12 * scale)
    assert np.abs(b.diagonal_value - a.data[a.diagonal]).max() > 1e-9 * scale
    np.testing.assert_array_equal(double.rhs, single.rhs)
    # the product with the diagonal apart is the matrix's
    x = np.random.default_rng(1).normal(size=single.rhs.size)
    dense = to_scipy(b).astype(np.float64) + sp.diags(b.diagonal_value)
    out = np.empty_like(x)
    linalg.multiply(b, x, out)
    np.testing.assert_allclose(out, dense @ x, rtol=0, atol=1e-12 * scale * np.abs(x).max())
    coarse = solvers.CoarseSpace(fluid.position[single.particles], fluid.domain_min, 4 * L0)
    p = np.zeros_like(single.rhs)
    iterations, residual, _ = solve(b, single.rhs, p, solver, 1e-10, 5000, coarse)
    assert 0 < iterations < 5000 and residual <= 1e-10
    r = single.rhs - dense @ p
    assert np.linalg.norm(r) <= 1.01e-10 * np.linalg.norm(single.rhs)


def test_a_change_of_matrix_precision_reaches_the_steps() -> None:
    """The matrix buffers a solver keeps from step to step follow its parameters: a step after
    ``params`` changed to single precision assembles in single precision (and back)."""
    fluid = dam_break(solver="deflated")
    fluid.step(5e-4)
    for precision, dtype in (("single", np.float32), ("double", np.float64)):
        fluid.params = dataclasses.replace(fluid.params, matrix_precision=precision)
        fluid.step(5e-4)
        assert fluid._matrix_buffers[1].dtype == dtype


def test_a_single_precision_run_follows_the_double_one() -> None:
    """The dam break 40 steps after release with the matrix in single precision: the same flow
    on another round-off path. Measured: pressures 6e-6 of the largest apart, positions 3e-8
    l0 (ten times closer than a solve to 1e-10 instead of 1e-8 leaves the double run: 6e-5
    and 2e-7); the bounds are ten times those. Rounding the diagonal as well left them 3e-3
    and 1e-5 l0 apart: that loses the differences p_j - p_i that A x is made of
    (docs/decisions.md)."""
    runs = []
    for precision in ("double", "single"):
        fluid = dam_break(solver="deflated", matrix_precision=precision)
        for _ in range(40):
            fluid.step(5e-4)
        runs.append(fluid)
    double, single = runs
    fluid_rows = double.kind == FLUID
    assert np.abs(double.velocity[fluid_rows]).max() > 0.1  # the column has fallen
    largest = double.pressure.max()
    assert np.abs(single.pressure - double.pressure).max() <= 6e-5 * largest
    assert np.abs(single.position - double.position).max() <= 3e-7 * L0
    assert np.any(single.position != double.position)


def test_deflated_solve_is_the_same_with_one_and_two_threads(released) -> None:
    matrix, rhs, coarse = released
    solutions = []
    for threads in (1, 2):
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        x = np.zeros_like(rhs)
        solve(matrix, rhs, x, "deflated", 1e-10, 5000, coarse)
        solutions.append(x)
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    assert np.array_equal(solutions[0], solutions[1])


def test_two_block_ordering_uncouples_the_blocks_and_solves_the_same_system(monkeypatch) -> None:
    """With the two-block order (poisson.number_unknowns) no entry joins block 0 and block 1,
    the separator is a thin slab, and ICCG gives the one-block solution to its tolerance in
    about as many iterations."""
    solver = dam_break()
    dt = 5e-4
    for _ in range(20):
        solver.step(dt)
    one = solver.poisson_system(dt)
    monkeypatch.setattr(mps, "TWO_BLOCK_ROWS", 0)
    two = solver.poisson_system(dt)
    b0, b1 = two.matrix.blocks
    n = two.rhs.size
    assert 0 < b0 < b1 < n and n - b1 < 0.25 * n
    assert np.array_equal(np.sort(two.particles), one.particles)
    a = to_scipy(two.matrix)
    assert a[:b0, b0:b1].nnz == 0 and a[b0:b1, :b0].nnz == 0
    # the same matrix, rows and columns permuted
    order = np.searchsorted(one.particles, two.particles)
    assert abs(to_scipy(one.matrix)[order][:, order] - a).max() == 0.0
    np.testing.assert_array_equal(two.rhs, one.rhs[order])
    counts = []
    solutions = []
    for system in (one, two):
        x = np.zeros(system.rhs.size)
        iterations, residual, _ = solve(system.matrix, system.rhs, x, "iccg", 1e-10, 5000)
        assert residual <= 1e-10
        counts.append(iterations)
        solutions.append(x)
    assert counts[1] <= counts[0] * 1.15
    np.testing.assert_allclose(
        solutions[1], solutions[0][order], rtol=0, atol=1e-7 * np.abs(solutions[0]).max()
    )


def test_ic0_breakdown_is_shifted() -> None:
    """An indefinite matrix makes IC(0) fail unshifted; a diagonal shift is applied and named."""
    indptr = np.array([0, 2, 4])
    indices = np.array([0, 1, 0, 1], dtype=np.int32)
    data = np.array([1.0, 1.05, 1.05, 1.0])
    matrix = linalg.Matrix(indptr, indices, data, np.array([0, 3]), np.array([2, 2]), np.empty(0))
    factor = np.zeros(4)
    assert not linalg.incomplete_cholesky(matrix, 0.0, factor)
    assert linalg.incomplete_cholesky(matrix, 0.1, factor)


@pytest.mark.parametrize("method", ["iccg", "deflated"])
def test_non_convergence_raises_fluid_diverged(method: str) -> None:
    solver = dam_break(max_iterations=2, solver=method)
    with pytest.raises(FluidDiverged) as caught:
        solver.step(5e-4)
    assert isinstance(caught.value, SimulationUnstable)
    assert caught.value.iterations == 2 and caught.value.residual > 1e-8
    assert caught.value.time == 0.0


@pytest.mark.parametrize("skin", [0.0, 0.5])
def test_restore_resumes_bitwise(skin: float) -> None:
    """With a neighbour skin the checkpoint holds the positions the Verlet list was built at
    (not the list): the resumed solver builds the same list from them, so the sums keep their
    order."""
    solver = dam_break(neighbour_skin=skin)
    for _ in range(5):
        solver.step(solver.stable_dt())
    saved = solver.state_arrays()
    assert ("neighbour_reference_position" in saved) == (skin > 0)
    for _ in range(5):
        solver.step(solver.stable_dt())
    resumed = dam_break(neighbour_skin=skin)
    resumed.restore(saved)
    for _ in range(5):
        resumed.step(resumed.stable_dt())
    for name, value in solver.state_arrays().items():
        assert np.array_equal(value, resumed.state_arrays()[name]), name


@pytest.mark.parametrize(("two_blocks", "skin"), [(False, 0.0), (True, 0.0), (False, 0.5)])
def test_result_does_not_depend_on_thread_count(two_blocks: bool, skin: float, monkeypatch) -> None:
    if two_blocks:  # the PPE of this small dam break in two blocks and a separator
        monkeypatch.setattr(mps, "TWO_BLOCK_ROWS", 0)
    results = []
    default = numba.get_num_threads()
    try:
        for threads in (1, default):
            numba.set_num_threads(threads)
            solver = dam_break(neighbour_skin=skin)
            for _ in range(5):
                solver.step(5e-4)
            results.append(solver.state_arrays())
    finally:
        numba.set_num_threads(default)
    for name in results[0]:
        assert np.array_equal(results[0][name], results[1][name]), name


def test_neighbour_skin_searches_less_and_follows_the_same_flow() -> None:
    """A Verlet list (skin 0.5 l0) is searched again only when a particle has moved a quarter
    of l0, not twice a step, and gives the flow of the fresh searches up to round-off (the sums
    run in another order)."""
    fresh, verlet = dam_break(), dam_break(neighbour_skin=0.5)
    for _ in range(40):
        dt = fresh.stable_dt()
        fresh.step(dt)
        verlet.step(dt)
    assert fresh.searches == 80
    assert 1 <= verlet.searches <= 20
    assert np.abs(verlet.position - fresh.position).max() < 1e-6 * L0
    rows = verlet.kind == FLUID
    verlet.neighbours(rows)
    before = verlet.searches
    verlet.neighbours(rows)
    assert verlet.searches == before  # nothing moved: cut from the same list
    verlet.position[0, 0] += 0.3 * L0  # past half the skin: searched afresh
    moved = verlet.neighbours(rows)
    assert verlet.searches == before + 1
    row = moved.indices[moved.start[0] : moved.start[1]]
    near = np.linalg.norm(verlet.position - verlet.position[0], axis=1) < verlet.search_radius
    near[0] = False
    assert sorted(row.tolist()) == np.flatnonzero(near & verlet.alive).tolist()


def test_dry_walls_without_rows_change_nothing(monkeypatch) -> None:
    """Walls with no water within the search radius get no neighbour-list row in a step: they
    are on the free surface either way, so the flow is bitwise that of rows for every wall."""
    wet = dam_break()
    for _ in range(30):
        wet.step(5e-4)
    rows = wet._wet(wet.neighbours(wet.kind == FLUID))
    assert rows is not None and 0 < rows[wet.kind != FLUID].sum() < (wet.kind != FLUID).sum() / 2
    monkeypatch.setattr(MPSSolver, "_wet", lambda self, start: None)
    every = dam_break()
    for _ in range(30):
        every.step(5e-4)
    for name in ("position", "velocity", "pressure", "alive"):
        assert np.array_equal(getattr(wet, name), getattr(every, name)), name


def test_three_dimensional_tank_runs() -> None:
    l0 = 0.01
    walls, wall_kinds = tank(0.06, 0.08, l0, dim=3, inner_depth=0.05)
    fluid = water_block(0, 0.06, 0, 0.05, l0, 0, 0.06)
    positions = np.vstack([fluid, walls])
    kinds = np.concatenate([np.full(len(fluid), FLUID, dtype=np.int8), wall_kinds])
    solver = MPSSolver(MPSParameters(dim=3, l0=l0), positions, kinds)
    for _ in range(10):
        stats = solver.step(solver.stable_dt())
    fluid_mask = solver.kind == FLUID
    assert stats.dead == 0 and stats.iterations > 0
    assert np.all(np.isfinite(solver.position))
    bottom = fluid_mask & (solver.position[:, 2] < 1.5 * l0)
    # bottom pressure of the same order as rho g h (0.06 m: 589 Pa)
    assert 200.0 < solver.pressure[bottom].mean() < 1500.0


def test_substep_covers_the_rest_in_equal_steps_within_the_limit() -> None:
    from jellysim.fluid.mps import substep

    assert substep(0.01, 0.02) == 0.01
    assert substep(0.05, 0.0065) == pytest.approx(0.05 / 8)
    # stepping to the end with a fixed limit gives equal steps, none shorter than half the limit
    remaining, steps = 0.05, []
    while remaining > 1e-15:
        dt = substep(remaining, 0.0065)
        steps.append(dt)
        remaining -= dt
    assert len(steps) == 8
    assert max(steps) - min(steps) < 1e-15


@pytest.mark.parametrize("kappa", [None, 0.035])
def test_step_at_rest_under_gravity(kappa: float | None) -> None:
    """Water at rest: with the free-fall floor the CFL step assumes a fall over the water's
    height, sqrt(2 g H); without it the acceleration limit kappa sqrt(l0 / g) sets the step,
    kappa = sqrt(courant) unless given."""
    g, height = 9.81, 2 * A  # the column's cell centres span 2a - l0; the extent adds l0
    floored = dam_break(acceleration_number=kappa)
    courant = floored.params.courant
    assert floored.stable_dt() == pytest.approx(courant * L0 / np.sqrt(2 * g * height), rel=1e-12)
    free = dam_break(acceleration_number=kappa, free_fall_floor=False)
    if kappa is None:  # the expression of old, to the bit: fluid-only runs are unchanged
        a = float(np.linalg.norm(free.params.gravity_vector))
        assert free.stable_dt() == math.sqrt(courant * L0 / a)
    else:
        assert free.stable_dt() == pytest.approx(kappa * math.sqrt(L0 / g), rel=1e-12)
    for bad in (0.0, -0.1):
        with pytest.raises(ValueError, match="acceleration_number"):
            MPSParameters(dim=2, l0=L0, acceleration_number=bad)


def test_either_density_surface_also_tests_the_start_density() -> None:
    """surface = "either-density" (docs/theory/fluid.md F7b): a particle whose number density
    was under beta n0 at the start of the step stays on the free surface (Dirichlet p = 0,
    no PPE row) even when n* has reached beta n0; the standard criterion tests n* alone. Only
    with the mixed source, which computes n^k."""
    with pytest.raises(ValueError, match="either-density"):
        MPSParameters(dim=2, l0=L0, surface="either-density")
    solver = dam_break(source="mixed", gradient="corrected", surface="either-density")
    c = solver.constants
    dt = 5e-4
    plain = solver.poisson_system(dt)  # no start density: n* alone, as "standard"
    interior = np.flatnonzero(plain.unknown & (solver.kind == FLUID))
    assert interior.size > 600
    start = np.full(solver.kind.shape, c.n0)
    chosen = interior[[0, interior.size // 2, -1]]
    start[chosen] = 0.9 * solver.params.beta * c.n0
    both = solver.poisson_system(dt, start_density=start)
    assert not both.unknown[chosen].any()
    others = np.ones(solver.kind.shape, dtype=bool)
    others[chosen] = False
    assert np.array_equal(both.unknown[others], plain.unknown[others])
    assert both.matrix.indptr.size == plain.matrix.indptr.size - chosen.size


def test_step_gives_the_surface_test_the_number_density_at_the_start_of_the_step() -> None:
    """What step() hands poisson_system as n^k is the number density at the positions the step
    starts from, for every live fluid and wall particle (docs/theory/fluid.md F7b), not n*: a
    twin solver stepped alike measures it at those positions independently."""
    scheme = {"source": "mixed", "gradient": "corrected", "surface": "either-density"}
    stepped, twin = dam_break(**scheme), dam_break(**scheme)
    dt = 5e-4
    for _ in range(10):
        stepped.step(dt)
        twin.step(dt)
    twin.poisson_system(dt)  # n at the twin's (the same) positions, into its number_density
    expected = twin.number_density.copy()
    seen: list[np.ndarray] = []
    build = stepped.poisson_system

    def spy(*args: object, start_density: np.ndarray | None = None, **kw: object) -> object:
        assert start_density is not None
        seen.append(start_density.copy())
        return build(*args, start_density=start_density, **kw)  # type: ignore[arg-type]

    stepped.poisson_system = spy  # type: ignore[method-assign]
    stepped.step(dt)
    assert len(seen) == 1
    solid = stepped.alive & (stepped.kind != DUMMY)
    np.testing.assert_allclose(seen[0][solid], expected[solid], rtol=1e-12, atol=1e-12)
    moved = np.abs(stepped.number_density - expected)[solid & (stepped.kind == FLUID)].max()
    assert moved > 1e-3  # n* of the step differs, so n^k was not confused with it


def test_pressure_solvers_are_chosen_by_name() -> None:
    """STYLE rule 7: the solvers are a registry by the scene's name for them; the scene schema
    offers exactly its names, and an unknown one is refused, not silently replaced."""
    from jellysim.config.schema import Fluid

    offered = {f.name: f for f in dataclasses.fields(Fluid)}["solver"].metadata["choices"]
    assert tuple(offered) == tuple(solvers.PRESSURE_SOLVERS) == ("iccg", "cg", "deflated")
    with pytest.raises(ValueError, match="allowed: iccg, cg, deflated"):
        MPSParameters(dim=2, l0=L0, solver="amg")
    matrix = linalg.Matrix(  # A = [2], one row, one block
        np.array([0, 1], dtype=np.int64), np.array([0], dtype=np.int32), np.array([2.0]),
        np.array([0], dtype=np.int64), np.array([1, 1], dtype=np.int64), np.empty(0),
    )  # fmt: skip
    with pytest.raises(ValueError, match="solver = 'amg'"):
        solve(matrix, np.ones(1), np.zeros(1), "amg")
    for name in ("iccg", "cg"):
        x = np.zeros(1)
        iterations, residual, _ = solve(matrix, np.ones(1), x, name, 1e-12, 10)
        assert x[0] == pytest.approx(0.5) and residual <= 1e-12 and iterations >= 1
