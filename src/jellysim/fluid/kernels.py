"""Compiled kernels of the MPS method [Koshizuka & Oka 1996] (equations in docs/theory/fluid.md).

Arrays: positions and velocities ``(N, D)`` float64 in m and m/s (D = 2 or 3, the same kernels
for both), pressure ``(N,)`` Pa, number density ``(N,)`` dimensionless, ``alive (N,)`` bool,
``kind (N,)`` int8 (FLUID, WALL, DUMMY of :mod:`jellysim.fluid.geometry`). Dead particles take
part in nothing.

Every parallel loop is a gather: particle i reads its neighbours and writes only its own row, so
results are bitwise identical whatever the number of threads. The pressure solver's reductions are
serial for the same reason.

Weight, Eq. (F1): ``w(r) = r_e / r - 1`` for ``r < r_e``, else 0.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from jellysim.fluid.geometry import DUMMY, FLUID

# fastmath limited to reassociation and contraction: no-NaN/no-inf assumptions would hide the
# divergence that the solver must report.
FAST = {"reassoc", "contract"}


class Constants(NamedTuple):
    """Model constants of one run (built once from MPSParameters and the reference lattice)."""

    dim: int
    re_number_density: float  # m
    re_gradient: float  # m
    re_laplacian: float  # m
    n0: float  # reference number density with re_number_density (PPE source, surface)
    n0_gradient: float  # with re_gradient (gradient and divergence models)
    n0_laplacian: float  # with re_laplacian (Laplacian model)
    lambda_laplacian: float  # m2, lambda of the Laplacian model, Eq. (F3)
    density: float  # rho, kg/m3
    kinematic_viscosity: float  # nu, m2/s


class Neighbours(NamedTuple):
    """Neighbour list in CSR form: particle i's neighbours are ``indices[start[i]:start[i+1]]``
    (live particles within ``radius`` of it, itself excluded) at distances ``distance`` (m)."""

    start: np.ndarray  # (N + 1,) int64
    indices: np.ndarray  # (M,) int32 (a quarter less to write and read than int64)
    distance: np.ndarray  # (M,) float64
    radius: float  # m


class Matrix(NamedTuple):
    """Square sparse matrix in CSR with sorted column indices (or, assembled for the deflated
    solver, unsorted: the diagonal first); ``diagonal[i]`` is the position of entry (i, i) in
    ``data``. ``blocks`` = (b0, b1): rows ``[0, b0)`` and ``[b0, b1)`` are
    two uncoupled blocks (no entry joins them), rows from b1 on the separator coupled to both;
    the IC(0) factor and its triangular solves treat the two blocks in parallel. (n, n): one
    block."""

    indptr: np.ndarray  # (n + 1,) int64
    indices: np.ndarray  # (nnz,) int32 (the products with A are bound by memory bandwidth)
    data: np.ndarray  # (nnz,) float64
    diagonal: np.ndarray  # (n,) int64
    blocks: np.ndarray  # (2,) int64


class Factor(NamedTuple):
    """The IC(0) factor L as the triangular solves read it: the strict lower triangle of L by
    rows, that of L^T (the strict upper triangle) by rows from the last to the first, so that
    both substitutions stream through memory forwards and gather (no scatter), with 32-bit
    column indices (the solves are bound by memory bandwidth), and 1 / L_ii.

    Entries stay in double precision: with a single-precision copy the solves still converge
    to the same residual, but the coarse dam break of tests/integration/test_fluid_run.py
    took another round-off path that blew up at t = 0.05 s (docs/performance.md)."""

    lower_start: np.ndarray  # (n + 1,) int64
    lower_indices: np.ndarray  # (nnz_lower,) int32
    lower_data: np.ndarray  # (nnz_lower,) float64
    upper_start: np.ndarray  # (n + 1,) int64, row n - 1 - t at t
    upper_indices: np.ndarray  # (nnz_lower,) int32
    upper_data: np.ndarray  # (nnz_lower,) float64
    inverse_diagonal: np.ndarray  # (n,) float64


@njit(cache=True)
def weight(r: float, re: float) -> float:
    """Eq. (F1): ``w = r_e / r - 1`` for ``0 < r < r_e``, else 0 (dimensionless)."""
    if r < re:
        return re / r - 1.0
    return 0.0


# ---------------------------------------------------------------------------- neighbour search


# Cells of side radius / CELLS_PER_RADIUS: particle i scans the (2 CELLS_PER_RADIUS + 1)^D cells
# around its own, a volume of (2 + 1 / CELLS_PER_RADIUS)^D radius^D (27 radius^3 with cells of
# side radius, 15.6 with half that).
CELLS_PER_RADIUS = 2


@njit(cache=True)
def _room(buffer: np.ndarray, size: int) -> np.ndarray:
    """``buffer`` if it holds ``size`` entries, else a new one a quarter larger than that.

    The large arrays of a step (neighbour lists, the PPE matrix) are written into buffers the
    solver keeps from step to step: a fresh array of tens of megabytes is mapped anew by the
    allocator each time, and touching its pages for the first time cost more than filling
    them (tank-3d at 54,000: 1.1 steps/s with fresh arrays, docs/performance.md)."""
    if buffer.shape[0] >= size:
        return buffer
    return np.empty(size + size // 4, dtype=buffer.dtype)


class _Grid(NamedTuple):
    """The cell list of :func:`neighbour_list`, always three axes (a 2-D grid has one cell
    along z and zero z coordinates, so that the 2-D search is the 3-D one with its loops over z
    cut to one cell and distances bit for bit the same). Cells are numbered with x fastest;
    members of a cell are in particle order, and the cells along x are one run of members."""

    cell: np.ndarray  # (N, 3) int64, the cell coordinates of each live particle
    shape: np.ndarray  # (3,) int64
    stride: np.ndarray  # (3,) int64
    start: np.ndarray  # (cells + 1,) int64, members of cell c are start[c]:start[c + 1]
    member: np.ndarray  # (M,) int64, particle indices in cell order
    member_position: np.ndarray  # (3, M) float64, their coordinates, one contiguous run per axis
    position: np.ndarray  # (3, N) float64, every particle's coordinates, per axis


@njit(cache=True)
def _grid(position: np.ndarray, alive: np.ndarray, radius: float) -> _Grid:
    """Cells of side ``radius / CELLS_PER_RADIUS`` over the live particles' bounding box, filled
    by a stable counting sort that also copies the members' coordinates in cell order."""
    n, dim = position.shape
    coordinates = np.zeros((3, n))
    for i in range(n):
        for k in range(dim):
            coordinates[k, i] = position[i, k]
    lower = np.zeros(3)
    upper = np.zeros(3)
    lower[:dim] = np.inf
    upper[:dim] = -np.inf
    for i in range(n):
        if alive[i]:
            for k in range(dim):
                lower[k] = min(lower[k], coordinates[k, i])
                upper[k] = max(upper[k], coordinates[k, i])
    inverse = CELLS_PER_RADIUS / radius
    shape = np.ones(3, dtype=np.int64)
    for k in range(dim):
        if upper[k] >= lower[k]:
            shape[k] = int((upper[k] - lower[k]) * inverse) + 1
    stride = np.array([1, shape[0], shape[0] * shape[1]], dtype=np.int64)
    n_cells = stride[2] * shape[2]
    cell_of = np.full(n, -1, dtype=np.int64)
    cell = np.zeros((n, 3), dtype=np.int64)
    start = np.zeros(n_cells + 1, dtype=np.int64)
    for i in range(n):
        if alive[i]:
            c = 0
            for k in range(dim):
                q = min(int((coordinates[k, i] - lower[k]) * inverse), shape[k] - 1)
                cell[i, k] = q
                c += q * stride[k]
            cell_of[i] = c
            start[c + 1] += 1
    for c in range(n_cells):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    member = np.empty(start[n_cells], dtype=np.int64)
    member_position = np.zeros((3, start[n_cells]))
    for i in range(n):
        if cell_of[i] >= 0:
            m = fill[cell_of[i]]
            member[m] = i
            for k in range(3):
                member_position[k, m] = coordinates[k, i]
            fill[cell_of[i]] += 1
    return _Grid(cell, shape, stride, start, member, member_position, coordinates)


@njit(cache=True)
def _scan_cells(
    i: int,
    cell: np.ndarray,
    shape: np.ndarray,
    stride: np.ndarray,
    start: np.ndarray,
    member: np.ndarray,
    member_position: np.ndarray,
    position: np.ndarray,
    radius2: float,
    index: np.ndarray,
    distance: np.ndarray,
    slot: int,
) -> int:
    """Particle i's neighbours closer than sqrt(radius2) in the cells around its own, in
    cell order then member order. With ``slot`` < 0 they are only counted; otherwise they are
    written from ``slot`` on into ``index`` and ``distance``. Returns how many there are.

    The loops are written out for three axes with the coordinates in separate arrays: the
    compiler then keeps the candidate loop free of inner loops (about twice as fast as a loop
    over D). The arguments are the fields of :class:`_Grid` (passed one by one: a tuple built
    inside a parallel function cannot be handed to its parallel loops)."""
    cx = cell[i, 0]
    cy = cell[i, 1]
    cz = cell[i, 2]
    first_x = max(cx - CELLS_PER_RADIUS, 0)
    last_x = min(cx + CELLS_PER_RADIUS, shape[0] - 1)
    xi = position[0, i]
    yi = position[1, i]
    zi = position[2, i]
    mx = member_position[0]
    my = member_position[1]
    mz = member_position[2]
    found = 0
    for qz in range(max(cz - CELLS_PER_RADIUS, 0), min(cz + CELLS_PER_RADIUS, shape[2] - 1) + 1):
        for qy in range(
            max(cy - CELLS_PER_RADIUS, 0), min(cy + CELLS_PER_RADIUS, shape[1] - 1) + 1
        ):
            c = qy * stride[1] + qz * stride[2]
            first = start[c + first_x]
            last = start[c + last_x + 1]
            if slot < 0:
                for m in range(first, last):
                    dx = mx[m] - xi
                    dy = my[m] - yi
                    dz = mz[m] - zi
                    found += dx * dx + dy * dy + dz * dz < radius2
            else:
                for m in range(first, last):
                    dx = mx[m] - xi
                    dy = my[m] - yi
                    dz = mz[m] - zi
                    r2 = dx * dx + dy * dy + dz * dz
                    if r2 < radius2:
                        j = member[m]
                        if j != i:
                            index[slot + found] = j
                            distance[slot + found] = math.sqrt(r2)
                            found += 1
    if slot < 0:
        found -= 1  # i itself, at distance 0
    return found


@njit(cache=True, parallel=True)
def search_neighbours(
    position: np.ndarray,
    alive: np.ndarray,
    rows: np.ndarray,
    radius: float,
    index: np.ndarray,
    distance: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cell-list search: for every live particle i with ``rows[i]`` ((N,) bool), all live
    particles closer than ``radius`` (m); other rows are empty (such particles still appear as
    neighbours of others).

    Cells of side ``radius / CELLS_PER_RADIUS`` (:func:`_grid`); particle i scans the cells
    within ``CELLS_PER_RADIUS`` of its own along each axis, once to count and once to fill.
    Returns the arrays of :class:`Neighbours` ``(start, indices, distance)``;
    within a row the order is fixed (cell order, then particle index). ``indices`` and
    ``distance`` are the buffers ``index`` ((K,) int32) and ``distance`` ((K,) float64) when
    they hold the list, else new ones (:func:`_room`), and run past the list's end ``start[N]``.
    """
    n = position.shape[0]
    cell, shape, stride, start, member, member_position, coordinates = _grid(
        position, alive, radius
    )
    radius2 = radius * radius
    # The rows to fill, compacted: the parallel loops split their iterations evenly between
    # the threads, and rows are not spread evenly over the particles (water first, then the
    # tank's walls mixed with its row-less dummies).
    active = np.flatnonzero(alive & rows)
    n_active = active.shape[0]
    row_count = np.zeros(n + 1, dtype=np.int64)
    none_i = np.empty(0, dtype=np.int32)
    none_f = np.empty(0)
    for a in prange(n_active):  # first pass: count each row
        i = active[a]
        row_count[i + 1] = _scan_cells(
            i, cell, shape, stride, start, member, member_position, coordinates, radius2,
            none_i, none_f, -1,
        )  # fmt: skip
    for i in range(n):
        row_count[i + 1] += row_count[i]
    index = _room(index, int(row_count[n]))
    distance = _room(distance, int(row_count[n]))
    for a in prange(n_active):  # second pass: fill each row
        i = active[a]
        _scan_cells(
            i, cell, shape, stride, start, member, member_position, coordinates, radius2,
            index, distance, row_count[i],
        )  # fmt: skip
    return row_count, index, distance


@njit(cache=True)
def neighbour_list(
    position: np.ndarray, alive: np.ndarray, rows: np.ndarray, radius: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`search_neighbours` into arrays of the list's own length."""
    start, index, distance = search_neighbours(
        position, alive, rows, radius, np.empty(0, dtype=np.int32), np.empty(0)
    )
    return start, index[: start[-1]].copy(), distance[: start[-1]].copy()


@njit(cache=True)
def _filter_row(
    i: int,
    candidates: Neighbours,
    x: np.ndarray,
    y: np.ndarray,
    z: np.ndarray,
    alive: np.ndarray,
    radius2: float,
    index: np.ndarray,
    distance: np.ndarray,
    slot: int,
) -> int:
    """Row i of a candidate list cut to its live entries closer than sqrt(radius2), in the
    candidates' order; counted only when ``slot`` < 0, else written from ``slot`` on."""
    xi = x[i]
    yi = y[i]
    zi = z[i]
    found = 0
    for m in range(candidates.start[i], candidates.start[i + 1]):
        j = candidates.indices[m]
        dx = x[j] - xi
        dy = y[j] - yi
        dz = z[j] - zi
        r2 = dx * dx + dy * dy + dz * dz
        if r2 < radius2 and alive[j]:
            if slot >= 0:
                index[slot + found] = j
                distance[slot + found] = math.sqrt(r2)
            found += 1
    return found


@njit(cache=True, parallel=True)
def filter_neighbours(
    candidates: Neighbours,
    position: np.ndarray,
    alive: np.ndarray,
    rows: np.ndarray,
    radius: float,
    index: np.ndarray,
    distance: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The neighbour list within ``radius`` (m) at ``position``, for the live particles with
    ``rows[i]``, taken from a list of ``candidates`` built at other positions with a larger
    radius (a Verlet list: it holds every pair now closer than ``radius`` while no particle
    has moved more than half the difference of the radii since it was built). Within a row,
    the candidates' order. Returns the arrays of :class:`Neighbours` in the buffers ``index``
    and ``distance`` (or new ones), like :func:`search_neighbours`; coordinates per axis as in
    :func:`_scan_cells`."""
    n, dim = position.shape
    coordinates = np.zeros((3, n))
    for i in prange(n):
        for k in range(dim):
            coordinates[k, i] = position[i, k]
    x = coordinates[0]
    y = coordinates[1]
    z = coordinates[2]
    active = np.flatnonzero(alive & rows)
    radius2 = radius * radius
    row_count = np.zeros(n + 1, dtype=np.int64)
    for a in prange(active.shape[0]):  # first pass: count each row
        i = active[a]
        row_count[i + 1] = _filter_row(i, candidates, x, y, z, alive, radius2, index, distance, -1)
    for i in range(n):
        row_count[i + 1] += row_count[i]
    index = _room(index, int(row_count[n]))
    distance = _room(distance, int(row_count[n]))
    for a in prange(active.shape[0]):  # second pass: fill each row
        i = active[a]
        _filter_row(i, candidates, x, y, z, alive, radius2, index, distance, row_count[i])
    return row_count, index, distance


@njit(cache=True, parallel=True)
def listed(neighbours: Neighbours, rows: np.ndarray) -> np.ndarray:
    """(N,) bool: the particles that appear in the rows ``rows`` ((R,) int64) of
    ``neighbours``. (Threads may store True into the same entry: the outcome is the same.)"""
    out = np.zeros(neighbours.start.shape[0] - 1, dtype=np.bool_)
    for a in prange(rows.shape[0]):
        i = rows[a]
        for m in range(neighbours.start[i], neighbours.start[i + 1]):
            out[neighbours.indices[m]] = True
    return out


@njit(cache=True, parallel=True)
def largest_displacement(position: np.ndarray, reference: np.ndarray, alive: np.ndarray) -> float:
    """The largest distance (m) of a live particle from its ``reference`` position."""
    n, dim = position.shape
    largest = np.zeros(n)
    for i in prange(n):
        if alive[i]:
            r2 = 0.0
            for k in range(dim):
                d = position[i, k] - reference[i, k]
                r2 += d * d
            largest[i] = r2
    return math.sqrt(largest.max()) if n else 0.0


# ------------------------------------------------------------------------------- particle models


@njit(cache=True)
def _fluid_rows(kind: np.ndarray, alive: np.ndarray) -> np.ndarray:
    """Indices of the live fluid particles. The particle models loop over these rather than
    over all particles: parallel loops split their iterations evenly between the threads, and
    the fluid particles are not spread evenly (water first, then the tank)."""
    return np.flatnonzero(alive & (kind == FLUID))


@njit(cache=True, parallel=True, fastmath=FAST)
def number_density(
    neighbours: Neighbours, alive: np.ndarray, re: float, out: np.ndarray, count: np.ndarray
) -> None:
    """Particle number density, Eq. (F2): ``n_i = sum_j w(|r_j - r_i|, r_e)`` over live particles
    of every kind (dummies included) into ``out`` (0 for particles without a neighbour-list row);
    ``count`` receives the number of neighbours
    closer than r_e (for neighbour-count surface detection)."""
    out[:] = 0.0
    count[:] = 0
    # live particles with a row, compacted (see _fluid_rows)
    active = np.flatnonzero(alive & (neighbours.start[1:] > neighbours.start[:-1]))
    for a in prange(active.shape[0]):
        i = active[a]
        total = 0.0
        found = 0
        for m in range(neighbours.start[i], neighbours.start[i + 1]):
            r = neighbours.distance[m]
            if r < re:
                total += weight(r, re)
                found += 1
        out[i] = total
        count[i] = found


@njit(cache=True, parallel=True, fastmath=FAST)
def explicit_stage(
    position: np.ndarray,
    velocity: np.ndarray,
    kind: np.ndarray,
    alive: np.ndarray,
    neighbours: Neighbours,
    constants: Constants,
    acceleration: np.ndarray,
    dt: float,
    out_position: np.ndarray,
    out_velocity: np.ndarray,
) -> None:
    """Explicit stage, Eq. (F5): temporary velocity and position of fluid particles.

    ``u*_i = u_i + dt (nu (2D / (lambda n0)) sum_j (u_j - u_i) w(r_ij, r_e,lap) + a_i)``,
    ``r*_i = r_i + dt u*_i``, summed over live neighbours of every kind (walls and dummies carry
    their own velocity, zero for a fixed tank: the no-slip wall). ``acceleration`` (N, D) m/s2:
    gravity plus external force over density. Other kinds are copied unchanged.
    """
    n, dim = position.shape
    re = constants.re_laplacian
    coefficient = (
        constants.kinematic_viscosity
        * 2.0
        * dim
        / (constants.lambda_laplacian * constants.n0_laplacian)
    )
    for i in prange(n):
        for k in range(dim):
            out_velocity[i, k] = velocity[i, k]
            out_position[i, k] = position[i, k]
    active = _fluid_rows(kind, alive)
    for a in prange(active.shape[0]):
        i = active[a]
        laplacian = np.zeros(dim)
        for m in range(neighbours.start[i], neighbours.start[i + 1]):
            r = neighbours.distance[m]
            if r < re:
                j = neighbours.indices[m]
                w = weight(r, re)
                for k in range(dim):
                    laplacian[k] += (velocity[j, k] - velocity[i, k]) * w
        for k in range(dim):
            u = velocity[i, k] + dt * (coefficient * laplacian[k] + acceleration[i, k])
            out_velocity[i, k] = u
            out_position[i, k] = position[i, k] + dt * u


@njit(cache=True, parallel=True, fastmath=FAST)
def collision(
    position: np.ndarray,
    velocity: np.ndarray,
    kind: np.ndarray,
    alive: np.ndarray,
    neighbours: Neighbours,
    distance: float,
    restitution: float,
    dt: float,
    out_position: np.ndarray,
    out_velocity: np.ndarray,
) -> None:
    """Collision model, Eq. (F6): pairs closer than ``distance`` (m) that approach each other
    exchange momentum as equal masses with restitution e.

    With ``e_ij = (r_j - r_i) / |r_j - r_i|`` and approach speed ``v_n = (u_i - u_j) . e_ij > 0``,
    fluid particle i receives ``-(1 + e) / 2 v_n e_ij`` from every such neighbour (all kinds;
    walls are not moved). All pairs use the velocities before the stage (Jacobi form), so a
    fluid pair's impulses are equal and opposite: fluid momentum is conserved exactly. The
    position moves by ``dt`` times the velocity change. Distances are recomputed from
    ``position``; ``neighbours`` only needs to contain every pair closer than ``distance``.
    """
    n, dim = position.shape
    half = 0.5 * (1.0 + restitution)
    for i in prange(n):
        for k in range(dim):
            out_velocity[i, k] = velocity[i, k]
            out_position[i, k] = position[i, k]
    active = _fluid_rows(kind, alive)
    for a in prange(active.shape[0]):
        i = active[a]
        for m in range(neighbours.start[i], neighbours.start[i + 1]):
            j = neighbours.indices[m]
            if not alive[j]:
                continue
            r2 = 0.0
            for k in range(dim):
                d = position[j, k] - position[i, k]
                r2 += d * d
            if r2 >= distance * distance or r2 == 0.0:
                continue
            r = math.sqrt(r2)
            approach = 0.0
            for k in range(dim):
                approach += (velocity[i, k] - velocity[j, k]) * (position[j, k] - position[i, k])
            approach /= r
            if approach <= 0.0:
                continue
            for k in range(dim):
                du = -half * approach * (position[j, k] - position[i, k]) / r
                out_velocity[i, k] += du
                out_position[i, k] += dt * du


@njit(cache=True, parallel=True, fastmath=FAST)
def velocity_divergence(
    position: np.ndarray,
    velocity: np.ndarray,
    kind: np.ndarray,
    alive: np.ndarray,
    neighbours: Neighbours,
    constants: Constants,
    out: np.ndarray,
) -> None:
    """Divergence model, Eq. (F9): ``(D / n0) sum_j (u_j - u_i) . (r_j - r_i) / r^2 w(r, r_e,grad)``
    (1/s) over live fluid and wall neighbours; 0 for other particles."""
    n, dim = position.shape
    re = constants.re_gradient
    coefficient = dim / constants.n0_gradient
    for i in prange(n):
        total = 0.0
        if alive[i] and kind[i] != DUMMY:
            for m in range(neighbours.start[i], neighbours.start[i + 1]):
                j = neighbours.indices[m]
                r = neighbours.distance[m]
                if r >= re or kind[j] == DUMMY:
                    continue
                dot = 0.0
                for k in range(dim):
                    dot += (velocity[j, k] - velocity[i, k]) * (position[j, k] - position[i, k])
                total += dot / (r * r) * weight(r, re)
        out[i] = coefficient * total


# ------------------------------------------------------------------------------ pressure Poisson


@njit(cache=True)
def number_unknowns(
    unknown: np.ndarray, position: np.ndarray, width: float, min_rows: int, out: np.ndarray
) -> np.ndarray:
    """Row number of each unknown particle (-1 for the others) into ``out``, in the order of
    :class:`Matrix`'s ``blocks``; returns (b0, b1, n) (int64).

    With fewer than ``min_rows`` unknowns, one block in particle order. Otherwise the unknowns
    are cut at the median of their coordinate along their longest extent: block 0 below
    ``median - width / 2``, block 1 from ``median + width / 2`` on, the separator between; each
    numbered in particle order. With ``width`` the coupling radius (m), no pair of block 0 and
    block 1 lies closer than it.
    """
    n, dim = position.shape
    count = 0
    for i in range(n):
        if unknown[i]:
            count += 1
    parts = np.array([count, count, count], dtype=np.int64)
    if count < max(min_rows, 1):
        row = 0
        for i in range(n):
            if unknown[i]:
                out[i] = row
                row += 1
            else:
                out[i] = -1
        return parts
    lower = np.full(dim, np.inf)
    upper = np.full(dim, -np.inf)
    for i in range(n):
        if unknown[i]:
            for k in range(dim):
                lower[k] = min(lower[k], position[i, k])
                upper[k] = max(upper[k], position[i, k])
    axis = np.argmax(upper - lower)
    coordinate = np.empty(count)
    row = 0
    for i in range(n):
        if unknown[i]:
            coordinate[row] = position[i, axis]
            row += 1
    middle = np.median(coordinate)
    block = np.full(n, -1, dtype=np.int64)
    size = np.zeros(3, dtype=np.int64)
    for i in range(n):
        if unknown[i]:
            x = position[i, axis]
            if x < middle - 0.5 * width:
                block[i] = 0
            elif x >= middle + 0.5 * width:
                block[i] = 1
            else:
                block[i] = 2
            size[block[i]] += 1
    fill = np.array([0, size[0], size[0] + size[1]], dtype=np.int64)
    for i in range(n):
        if block[i] >= 0:
            out[i] = fill[block[i]]
            fill[block[i]] += 1
        else:
            out[i] = -1
    parts[0] = size[0]
    parts[1] = size[0] + size[1]
    return parts


@njit(cache=True, parallel=True)
def assemble_poisson(
    neighbours: Neighbours,
    kind: np.ndarray,
    alive: np.ndarray,
    row_of: np.ndarray,
    n_rows: int,
    constants: Constants,
    diagonal_shift: float,
    sort_columns: bool,
    buffers: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Matrix of the pressure Poisson equation, Eq. (F8), over the unknown particles (live fluid
    and wall particles not on the free surface; ``row_of`` numbers them).

    ``A p = b`` with ``-(2D / (lambda n0)) sum_j (p_j - p_i) w(r_ij, r_e,lap) + c p_i``:
    off-diagonal ``A_ij = -a_ij`` for unknown neighbours j, ``a_ij = (2D / (lambda n0)) w``;
    diagonal ``sum_j a_ij`` over live fluid and wall neighbours (free-surface neighbours, p_j = 0,
    enter only here) plus ``diagonal_shift`` = c (the compressibility term, 1/m2). Symmetric,
    weakly diagonally dominant, positive definite when c > 0 or a Dirichlet neighbour is reached.
    Returns (indptr, indices, data, diagonal) of :class:`Matrix`, columns sorted per row; with
    ``sort_columns`` False each row is the diagonal followed by the neighbours in neighbour-list
    order (for solvers that need no order: the serial sort is skipped). ``buffers``: arrays
    reused for the rows in neighbour order (int32 and float64) and the sorted ones (likewise),
    see :func:`_room`; the returned (indices, data) run past ``indptr[-1]``, and the two
    buffers of the other order come after them, to be passed again next time.
    """
    n = kind.shape[0]
    re = constants.re_laplacian
    coefficient = 2.0 * constants.dim / (constants.lambda_laplacian * constants.n0_laplacian)
    particle_of = np.empty(n_rows, dtype=np.int64)
    for i in range(n):
        if row_of[i] >= 0:
            particle_of[row_of[i]] = i
    indptr = np.zeros(n_rows + 1, dtype=np.int64)
    for row in prange(n_rows):
        i = particle_of[row]
        found = 1
        for m in range(neighbours.start[i], neighbours.start[i + 1]):
            if neighbours.distance[m] < re and row_of[neighbours.indices[m]] >= 0:
                found += 1
        indptr[row + 1] = found
    for row in range(n_rows):
        indptr[row + 1] += indptr[row]
    # Rows in neighbour order, the diagonal first
    unsorted_indices = _room(buffers[0], indptr[n_rows])
    unsorted_data = _room(buffers[1], indptr[n_rows])
    for row in prange(n_rows):
        i = particle_of[row]
        start = indptr[row]
        end = start + 1
        unsorted_indices[start] = row
        total = 0.0
        for m in range(neighbours.start[i], neighbours.start[i + 1]):
            r = neighbours.distance[m]
            j = neighbours.indices[m]
            if r >= re or kind[j] == DUMMY or not alive[j]:
                continue
            a = coefficient * weight(r, re)
            total += a
            if row_of[j] >= 0:
                unsorted_indices[end] = row_of[j]
                unsorted_data[end] = -a
                end += 1
        unsorted_data[start] = total + diagonal_shift
    if not sort_columns:
        return indptr, unsorted_indices, unsorted_data, indptr[:-1].copy(), buffers[2], buffers[3]
    # Sorted columns by transposition: A is symmetric to the last bit (r_ij and r_ji are the
    # same floating-point numbers), and sweeping the rows in order appends to each transposed
    # row its columns in increasing order.
    indices = _room(buffers[2], indptr[n_rows])
    data = _room(buffers[3], indptr[n_rows])
    diagonal = np.empty(n_rows, dtype=np.int64)
    fill = indptr[:-1].copy()
    for row in range(n_rows):
        for p in range(indptr[row], indptr[row + 1]):
            column = unsorted_indices[p]
            q = fill[column]
            fill[column] += 1
            indices[q] = row
            data[q] = unsorted_data[p]
            if column == row:
                diagonal[row] = q
    return indptr, indices, data, diagonal, unsorted_indices, unsorted_data


@njit(cache=True, parallel=True, fastmath=FAST)
def multiply(matrix: Matrix, x: np.ndarray, out: np.ndarray) -> None:
    """``out = A x`` (row-wise gather)."""
    for row in prange(matrix.indptr.shape[0] - 1):
        total = 0.0
        for p in range(matrix.indptr[row], matrix.indptr[row + 1]):
            total += matrix.data[p] * x[matrix.indices[p]]
        out[row] = total


@njit(cache=True)
def _factor_rows(
    matrix: Matrix,
    shift: float,
    first: int,
    last: int,
    dense_row: np.ndarray,
    upper_fill: np.ndarray,
    out: np.ndarray,
) -> bool:
    """IC(0) rows ``[first, last)`` of :func:`incomplete_cholesky`, given the rows they refer
    to; ``dense_row`` (n,) zeros, left zero; ``upper_fill`` (n,) the next free upper entry of
    each row, where L_ik is copied as (L^T)_ki."""
    indptr = matrix.indptr
    indices = matrix.indices
    diagonal = matrix.diagonal
    for i in range(first, last):
        start = indptr[i]
        for p in range(start, diagonal[i]):
            k = indices[p]
            total = matrix.data[p]
            for b in range(indptr[k], diagonal[k]):
                total -= dense_row[indices[b]] * out[b]
            out[p] = total / out[diagonal[k]]
            dense_row[k] = out[p]
            # rows i come in increasing order: row k's upper entries fill in column order
            out[upper_fill[k]] = out[p]
            upper_fill[k] += 1
        pivot = matrix.data[diagonal[i]] * (1.0 + shift)
        for p in range(start, diagonal[i]):
            pivot -= out[p] * out[p]
            dense_row[indices[p]] = 0.0
        if not pivot > 0.0:
            return False
        out[diagonal[i]] = math.sqrt(pivot)
    return True


@njit(cache=True, parallel=True)
def incomplete_cholesky(matrix: Matrix, shift: float, out: np.ndarray) -> bool:
    """IC(0): ``L L^T ~ A + shift diag(A)`` with L on the lower pattern of A, Eq. (F11).

    ``out`` has A's layout (``matrix.data``'s shape); its lower-triangle entries, diagonal
    included, receive L, its upper entries L^T. Row by row:
    ``L_ik = (A_ik - sum_{m<k} L_im L_km) / L_kk`` over the common pattern,
    ``L_ii = sqrt(A_ii (1 + shift) - sum_{m<i} L_im^2)``. Returns False on a non-positive pivot.

    Row i's finished entries are scattered into a dense row (zero off the pattern), so the sum
    over m runs over row k's pattern alone, in column order, without merging the two rows. The
    two blocks of ``matrix.blocks`` are factored in parallel, then the separator.
    """
    n = matrix.indptr.shape[0] - 1
    bounds = np.array([0, matrix.blocks[0], matrix.blocks[1]], dtype=np.int64)
    upper_fill = matrix.diagonal + 1
    ok = np.ones(2, dtype=np.bool_)
    for block in prange(2):
        dense_row = np.zeros(n)
        ok[block] = _factor_rows(
            matrix, shift, bounds[block], bounds[block + 1], dense_row, upper_fill, out
        )
    if not (ok[0] and ok[1]):
        return False
    return _factor_rows(matrix, shift, matrix.blocks[1], n, np.zeros(n), upper_fill, out)


@njit(cache=True, parallel=True)
def compact_factor(matrix: Matrix, factor: np.ndarray) -> Factor:
    """The :class:`Factor` of an IC(0) factor in A's layout (from :func:`incomplete_cholesky`)."""
    n = matrix.indptr.shape[0] - 1
    lower_start = np.zeros(n + 1, dtype=np.int64)
    upper_start = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        lower_start[i + 1] = lower_start[i] + matrix.diagonal[i] - matrix.indptr[i]
    for t in range(n):  # row i = n - 1 - t
        upper_start[t + 1] = upper_start[t] + matrix.indptr[n - t] - matrix.diagonal[n - 1 - t] - 1
    lower_indices = np.empty(lower_start[n], dtype=np.int32)
    lower_data = np.empty(lower_start[n])
    upper_indices = np.empty(upper_start[n], dtype=np.int32)
    upper_data = np.empty(upper_start[n])
    inverse_diagonal = np.empty(n)
    for i in prange(n):
        q = lower_start[i]
        for p in range(matrix.indptr[i], matrix.diagonal[i]):
            lower_indices[q] = matrix.indices[p]
            lower_data[q] = factor[p]
            q += 1
        q = upper_start[n - 1 - i]
        for p in range(matrix.diagonal[i] + 1, matrix.indptr[i + 1]):
            upper_indices[q] = matrix.indices[p]
            upper_data[q] = factor[p]
            q += 1
        inverse_diagonal[i] = 1.0 / factor[matrix.diagonal[i]]
    return Factor(
        lower_start, lower_indices, lower_data, upper_start, upper_indices, upper_data,
        inverse_diagonal,
    )  # fmt: skip


def no_factor() -> Factor:
    """An empty :class:`Factor`, for plain CG."""
    start = np.zeros(1, dtype=np.int64)
    indices = np.empty(0, dtype=np.int32)
    data = np.empty(0)
    return Factor(start, indices, data, start, indices, data, np.empty(0))


@njit(cache=True)
def _forward(factor: Factor, r: np.ndarray, z: np.ndarray, first: int, last: int) -> None:
    """Forward substitution ``L z = r`` on rows ``[first, last)``."""
    for i in range(first, last):
        total = 0.0
        for p in range(factor.lower_start[i], factor.lower_start[i + 1]):
            total += factor.lower_data[p] * z[factor.lower_indices[p]]
        z[i] = (r[i] - total) * factor.inverse_diagonal[i]


@njit(cache=True)
def _backward(factor: Factor, z: np.ndarray, first: int, last: int) -> None:
    """Backward substitution ``L^T z = z`` on rows ``last - 1`` down to ``first``."""
    n = z.shape[0]
    for t in range(n - last, n - first):
        i = n - 1 - t
        total = 0.0
        for p in range(factor.upper_start[t], factor.upper_start[t + 1]):
            total += factor.upper_data[p] * z[factor.upper_indices[p]]
        z[i] = (z[i] - total) * factor.inverse_diagonal[i]


@njit(cache=True, parallel=True)
def _precondition(blocks: np.ndarray, factor: Factor, r: np.ndarray, z: np.ndarray) -> None:
    """``z = (L L^T)^-1 r``: forward substitution on L's rows, then backward substitution on
    L^T's rows. The two blocks of ``blocks`` (:class:`Matrix`) in parallel: forward blocks
    then separator, backward separator then blocks."""
    n = r.shape[0]
    bounds = np.array([0, blocks[0], blocks[1]], dtype=np.int64)
    for block in prange(2):
        _forward(factor, r, z, bounds[block], bounds[block + 1])
    _forward(factor, r, z, blocks[1], n)
    _backward(factor, z, blocks[1], n)
    for block in prange(2):
        _backward(factor, z, bounds[block], bounds[block + 1])


@njit(cache=True)
def dot(a: np.ndarray, b: np.ndarray) -> float:
    """``a . b``, summed serially (the same result whatever the number of threads)."""
    total = 0.0
    for i in range(a.shape[0]):
        total += a[i] * b[i]
    return total


@njit(cache=True)
def conjugate_gradient(
    matrix: Matrix,
    factor: Factor,
    preconditioned: bool,
    b: np.ndarray,
    x: np.ndarray,
    tolerance: float,
    max_iterations: int,
) -> tuple[int, float]:
    """(Preconditioned) conjugate gradients for ``A x = b``, Eq. (F12), from the initial guess
    in ``x`` (overwritten by the solution). Stops when ``|b - A x| <= tolerance |b|``.

    With ``preconditioned`` the IC(0) factor ``factor`` (:func:`compact_factor`) preconditions;
    otherwise plain CG (``factor`` unused). Returns (iterations, relative residual).
    """
    n = b.shape[0]
    norm_b = math.sqrt(dot(b, b))
    if n == 0:
        return 0, 0.0
    if norm_b == 0.0:
        x[:] = 0.0
        return 0, 0.0
    r = np.empty(n)
    multiply(matrix, x, r)
    for i in range(n):
        r[i] = b[i] - r[i]
    z = np.empty(n)
    if preconditioned:
        _precondition(matrix.blocks, factor, r, z)
    else:
        z[:] = r
    d = z.copy()
    q = np.empty(n)
    rz = dot(r, z)
    residual = math.sqrt(dot(r, r)) / norm_b
    iterations = 0
    while residual > tolerance and iterations < max_iterations:
        multiply(matrix, d, q)
        curvature = dot(d, q)
        if curvature == 0.0 or rz == 0.0:
            break  # the residual is exactly zero in exact arithmetic: nothing left to reduce
        alpha = rz / curvature
        for i in range(n):
            x[i] += alpha * d[i]
            r[i] -= alpha * q[i]
        iterations += 1
        residual = math.sqrt(dot(r, r)) / norm_b
        if not math.isfinite(residual):
            break
        if preconditioned:
            _precondition(matrix.blocks, factor, r, z)
        else:
            z[:] = r
        rz_new = dot(r, z)
        beta = rz_new / rz
        rz = rz_new
        for i in range(n):
            d[i] = z[i] + beta * d[i]
    return iterations, residual


# ------------------------------------------------------------------------------------ correction


# Corrected gradient (Eq. F10a): the moment matrix is inverted only where det(C) is at least
# this (1 on a full lattice, about 0.5 at a flat free surface or wall); fewer or one-sided
# neighbours (a splash) keep the uncorrected gradient.
CORRECTION_MIN_DETERMINANT = 0.3


@njit(cache=True)
def _solve_small(matrix: np.ndarray, vector: np.ndarray) -> bool:
    """Solve ``matrix x = vector`` in place in ``vector`` for a symmetric 2x2 or 3x3 matrix by
    Cramer's rule; False (``vector`` unchanged) when det < CORRECTION_MIN_DETERMINANT."""
    if matrix.shape[0] == 2:
        a, b, d = matrix[0, 0], matrix[0, 1], matrix[1, 1]
        det = a * d - b * b
        if det < CORRECTION_MIN_DETERMINANT:
            return False
        x = (d * vector[0] - b * vector[1]) / det
        y = (a * vector[1] - b * vector[0]) / det
        vector[0] = x
        vector[1] = y
        return True
    m = matrix
    c00 = m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]
    c01 = m[1, 2] * m[2, 0] - m[1, 0] * m[2, 2]
    c02 = m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]
    det = m[0, 0] * c00 + m[0, 1] * c01 + m[0, 2] * c02
    if det < CORRECTION_MIN_DETERMINANT:
        return False
    c11 = m[0, 0] * m[2, 2] - m[0, 2] * m[2, 0]
    c12 = m[0, 2] * m[1, 0] - m[0, 0] * m[1, 2]
    c22 = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
    v0, v1, v2 = vector[0], vector[1], vector[2]
    # inverse = adjugate / det; the adjugate of a symmetric matrix is symmetric
    vector[0] = (c00 * v0 + c01 * v1 + c02 * v2) / det
    vector[1] = (c01 * v0 + c11 * v1 + c12 * v2) / det
    vector[2] = (c02 * v0 + c12 * v1 + c22 * v2) / det
    return True


@njit(cache=True, fastmath=FAST)
def _surface_repulsion(
    i: int,
    position: np.ndarray,
    pressure: np.ndarray,
    kind: np.ndarray,
    neighbours: Neighbours,
    constants: Constants,
    gradient: np.ndarray,
) -> None:
    """Add Eq. (F10b), the tangential repulsion of free-surface particle i, to its gradient
    sum ``gradient`` (the raw sum, before the factor D / n0; :func:`pressure_correction`)."""
    dim = position.shape[1]
    re = constants.re_gradient
    highest = pressure[i]
    push = np.zeros(dim)
    normal = np.zeros(dim)
    for m in range(neighbours.start[i], neighbours.start[i + 1]):
        j = neighbours.indices[m]
        r = neighbours.distance[m]
        if kind[j] == DUMMY or r >= constants.re_laplacian or r == 0.0:
            continue
        w = weight(r, constants.re_laplacian) / r
        for k in range(dim):
            normal[k] -= w * (position[j, k] - position[i, k])
        if r < re:
            if kind[j] == FLUID:
                highest = max(highest, pressure[j])
            w = weight(r, re) / (r * r)
            for k in range(dim):
                push[k] += w * (position[j, k] - position[i, k])
    size = np.sqrt(np.sum(normal * normal))
    if size == 0.0:
        return
    along = np.sum(push * normal) / (size * size)
    for k in range(dim):
        gradient[k] += (highest - pressure[i]) * (push[k] - along * normal[k])


@njit(cache=True, parallel=True, fastmath=FAST)
def pressure_correction(
    position: np.ndarray,
    velocity: np.ndarray,
    pressure: np.ndarray,
    kind: np.ndarray,
    alive: np.ndarray,
    neighbours: Neighbours,
    constants: Constants,
    dt: float,
    out_position: np.ndarray,
    out_velocity: np.ndarray,
    corrected: bool = False,
    surface: np.ndarray | None = None,
) -> None:
    """Pressure gradient with the minimum neighbour pressure, Eq. (F10), and the correction of
    fluid particles, Eq. (F13):

    ``grad p_i = (D / n0) sum_j (p_j - p_min,i) / r_ij^2 (r_j - r_i) w(r_ij, r_e,grad)``, with
    ``p_min,i`` the least pressure among i and its fluid and wall neighbours within r_e,grad
    (dummies are ignored); ``u_i += -dt grad p_i / rho``, ``r_i += dt`` times that change.
    With ``corrected``, Eq. (F10a): the gradient is multiplied by the inverse of the moment
    matrix ``C_i = (D / n0) sum_j w (r_j - r_i) (r_j - r_i)^T / r_ij^2`` over the same
    neighbours [Khayyer & Gotoh 2011]. C_i is the identity on a full lattice and not where the
    neighbourhood is one-sided (the free surface, a wall); there the corrected gradient is exact
    for a linear pressure when p_i is the least of its neighbourhood (the top layer under
    gravity), and otherwise off by the minimum-pressure term only.
    ``surface`` ((N,) bool, or None for none): the free-surface particles given the tangential
    repulsion of Eq. (F10b), ``(p_max,i - p_i) sum_j (r_j - r_i) w / r_ij^2`` (the sum over i's
    fluid and wall neighbours within r_e,grad, p_max,i the largest pressure among its fluid
    neighbours there) with its component along the surface normal removed; the normal is the
    direction away from the centroid of the fluid and wall neighbours within the Laplacian
    radius, ``-sum_j (r_j - r_i) w(r, r_e,lap) / r``. Other kinds are copied unchanged.
    """
    n, dim = position.shape
    re = constants.re_gradient
    coefficient = -dt * dim / (constants.n0_gradient * constants.density)
    for i in prange(n):
        for k in range(dim):
            out_velocity[i, k] = velocity[i, k]
            out_position[i, k] = position[i, k]
    active = _fluid_rows(kind, alive)
    for a in prange(active.shape[0]):
        i = active[a]
        lowest = pressure[i]
        for m in range(neighbours.start[i], neighbours.start[i + 1]):
            j = neighbours.indices[m]
            if neighbours.distance[m] < re and kind[j] != DUMMY:
                lowest = min(lowest, pressure[j])
        gradient = np.zeros(dim)
        for m in range(neighbours.start[i], neighbours.start[i + 1]):
            j = neighbours.indices[m]
            r = neighbours.distance[m]
            if r >= re or kind[j] == DUMMY:
                continue
            scale = (pressure[j] - lowest) / (r * r) * weight(r, re)
            for k in range(dim):
                gradient[k] += scale * (position[j, k] - position[i, k])
        if corrected:  # a pass of its own: the standard path allocates and sums nothing more
            moments = np.zeros((dim, dim))
            for m in range(neighbours.start[i], neighbours.start[i + 1]):
                j = neighbours.indices[m]
                r = neighbours.distance[m]
                if r >= re or kind[j] == DUMMY:
                    continue
                w = weight(r, re) / (r * r)
                for k in range(dim):
                    for q in range(dim):
                        moments[k, q] += (
                            w
                            * (position[j, k] - position[i, k])
                            * (position[j, q] - position[i, q])
                        )
            moments *= dim / constants.n0_gradient
            _solve_small(moments, gradient)
        if surface is not None and surface[i]:
            _surface_repulsion(i, position, pressure, kind, neighbours, constants, gradient)
        for k in range(dim):
            du = coefficient * gradient[k]
            out_velocity[i, k] += du
            out_position[i, k] += dt * du
