"""Sparse linear algebra of the pressure solve: CSR products, IC(0) and conjugate gradients.

Reductions are serial and parallel loops are gathers (each writes its own row), so results are
bitwise identical whatever the number of threads.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

# fastmath limited to reassociation and contraction: no-NaN/no-inf assumptions would hide the
# divergence that the solver must report.
FAST = {"reassoc", "contract"}


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
