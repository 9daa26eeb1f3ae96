"""The pressure Poisson equation of MPS, Eq. (F8): numbering of the unknowns and assembly of
its matrix (equations in docs/theory/fluid.md).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from jellysim.fluid.geometry import DUMMY
from jellysim.fluid.kernels import Constants, weight
from jellysim.fluid.neighbours import Neighbours, room


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
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
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
    see :func:`room`; the returned (indices, data) run past ``indptr[-1]``, and the two
    buffers of the other order come after them, to be passed again next time.

    With real buffers of single precision (fluid.matrix_precision = "single") the off-diagonal
    entries are rounded to it and the diagonal, in double, sums the rounded a_ij of the
    unknown neighbours: each row's excess over them (its free-surface neighbours' a_ij and
    the shift) is the double one, so A x keeps the double precision of the differences
    p_j - p_i that it is made of (docs/decisions.md). The diagonal is then returned last,
    (n_rows,) float64, and its slots in ``data`` hold 0; otherwise the last array is empty.
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
    unsorted_indices = room(buffers[0], indptr[n_rows])
    unsorted_data = room(buffers[1], indptr[n_rows])
    single = unsorted_data.itemsize == 4  # float32 buffers: fluid.matrix_precision single
    diagonal_value = np.empty(n_rows if single else 0)
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
            if row_of[j] >= 0:
                if single:
                    a = float(np.float32(a))
                unsorted_indices[end] = row_of[j]
                unsorted_data[end] = -a
                end += 1
            total += a
        if single:
            unsorted_data[start] = 0.0
            diagonal_value[row] = total + diagonal_shift
        else:
            unsorted_data[start] = total + diagonal_shift
    if not sort_columns:
        return (
            indptr, unsorted_indices, unsorted_data, indptr[:-1].copy(), buffers[2], buffers[3],
            diagonal_value,
        )  # fmt: skip
    # Sorted columns by transposition: A is symmetric to the last bit (r_ij and r_ji are the
    # same floating-point numbers), and sweeping the rows in order appends to each transposed
    # row its columns in increasing order.
    indices = room(buffers[2], indptr[n_rows])
    data = room(buffers[3], indptr[n_rows])
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
    return indptr, indices, data, diagonal, unsorted_indices, unsorted_data, diagonal_value
