"""Sparse linear algebra of the pressure solve: CSR products, IC(0), and the one preconditioned
conjugate gradient of the package (:func:`preconditioned_cg`, also the soft bell's implicit springs
and the deflated solver).

Reductions are serial and parallel loops are gathers (each writes its own row), so results are
bitwise identical whatever the number of threads.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol, TypeVar

import numpy as np
from numba import njit, prange, types
from numba.extending import overload_method, register_jitable

# fastmath limited to contraction (a * b + c as one fused multiply-add): no-NaN/no-inf
# assumptions would hide the divergence that the solver must report, and reassociation let LLVM
# vectorise the sums over neighbours with gathers, which made a product with A 2.7 times slower
# on an AVX-512 host (AMD EPYC) and put the vector width into the order of every sum
# (docs/decisions.md, "Sums in the written order").
FAST = {"contract"}


class LinearOperator(Protocol):
    """A symmetric positive definite A: ``apply(x, out)`` writes ``out = A x`` ((n,) float64)."""

    def apply(self, x: np.ndarray, out: np.ndarray) -> None: ...


class Preconditioner(Protocol):
    """``precondition(r, z)`` writes ``z = M^-1 r`` ((n,) float64), M symmetric positive
    definite."""

    def precondition(self, r: np.ndarray, z: np.ndarray) -> None: ...


# The NamedTuple classes whose apply / precondition compiled code may call (one overload per
# method name, which looks the class up here: two overloads of one method name on NamedTuples
# collide in Numba's lowering). Numba requires the overloads' parameters, annotations included,
# to be the methods' own.
_OPERATORS: set[type] = set()
_PRECONDITIONERS: set[type] = set()
Kind = TypeVar("Kind", bound=type)


def linear_operator(cls: Kind) -> Kind:
    """Class decorator: the NamedTuple ``cls``'s ``apply`` (whose body calls compiled kernels)
    becomes callable from compiled code too, resolved when the caller is compiled, so callers
    stay cacheable (a jitted function passed as an argument would not be)."""
    _OPERATORS.add(cls)
    return cls


def preconditioner(cls: Kind) -> Kind:
    """Class decorator: as :func:`linear_operator`, for the method ``precondition``."""
    _PRECONDITIONERS.add(cls)
    return cls


@overload_method(types.BaseNamedTuple, "apply")
def _compiled_apply(self, x: np.ndarray, out: np.ndarray):
    if self.instance_class in _OPERATORS:
        return self.instance_class.apply
    return None


@overload_method(types.BaseNamedTuple, "precondition")
def _compiled_precondition(self, r: np.ndarray, z: np.ndarray):
    if self.instance_class in _PRECONDITIONERS:
        return self.instance_class.precondition
    return None


@linear_operator
class Matrix(NamedTuple):
    """Square sparse matrix in CSR with sorted column indices (or, assembled for the deflated
    solver, unsorted: the diagonal first); ``diagonal[i]`` is the position of entry (i, i) in
    ``data``. ``blocks`` = (b0, b1): rows ``[0, b0)`` and ``[b0, b1)`` are
    two uncoupled blocks (no entry joins them), rows from b1 on the separator coupled to both;
    the IC(0) factor and its triangular solves treat the two blocks in parallel. (n, n): one
    block."""

    indptr: np.ndarray  # (n + 1,) int64
    indices: np.ndarray  # (nnz,) int32 (the products with A are bound by memory bandwidth)
    data: np.ndarray  # (nnz,) float64, or float32 (see diagonal_value)
    diagonal: np.ndarray  # (n,) int64
    blocks: np.ndarray  # (2,) int64
    # Empty, or with ``data`` in single precision (fluid.matrix_precision) the diagonal in double,
    # (n,) float64: ``data``'s diagonal slots then hold 0 (:func:`diagonal_values`).
    diagonal_value: np.ndarray

    def apply(self, x: np.ndarray, out: np.ndarray) -> None:
        """``out = A x``."""
        multiply(self, x, out)


@preconditioner
class Factor(NamedTuple):
    """The IC(0) factor L as the triangular solves read it: the strict lower triangle of L by
    rows, that of L^T (the strict upper triangle) by rows from the last to the first, so that
    both substitutions stream through memory forwards and gather (no scatter), with 32-bit
    column indices (the solves are bound by memory bandwidth), and 1 / L_ii; ``blocks`` those
    of the :class:`Matrix` factored.

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
    blocks: np.ndarray  # (2,) int64

    def precondition(self, r: np.ndarray, z: np.ndarray) -> None:
        """``z = (L L^T)^-1 r``, Eq. (F11)."""
        _precondition(self, r, z)


@preconditioner
class Identity(NamedTuple):
    """No preconditioner: ``z = r`` (plain CG). ``rows`` n: compiled code cannot call the
    method of an empty NamedTuple."""

    rows: int

    def precondition(self, r: np.ndarray, z: np.ndarray) -> None:
        """``z = r``."""
        z[:] = r


@njit(cache=True, parallel=True, fastmath=FAST)
def multiply(matrix: Matrix, x: np.ndarray, out: np.ndarray) -> None:
    """``out = A x`` (row-wise gather; with a diagonal in double, ``diagonal_value``, it first,
    then the row's entries, whose diagonal slot holds 0)."""
    split = matrix.diagonal_value.shape[0] > 0
    for row in prange(matrix.indptr.shape[0] - 1):
        total = 0.0
        if split:
            total = matrix.diagonal_value[row] * x[row]
        for p in range(matrix.indptr[row], matrix.indptr[row + 1]):
            total += matrix.data[p] * x[matrix.indices[p]]
        out[row] = total


@njit(cache=True)
def diagonal_values(matrix: Matrix) -> np.ndarray:
    """A's diagonal, (n,) float64: ``diagonal_value``, or the diagonal entries of ``data``."""
    if matrix.diagonal_value.shape[0] > 0:
        return matrix.diagonal_value.copy()
    out = np.empty(matrix.diagonal.shape[0])
    for i in range(matrix.diagonal.shape[0]):
        out[i] = matrix.data[matrix.diagonal[i]]
    return out


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
        if matrix.diagonal_value.shape[0] > 0:
            pivot = matrix.diagonal_value[i] * (1.0 + shift)
        else:
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
        inverse_diagonal, matrix.blocks,
    )  # fmt: skip


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
def _precondition(factor: Factor, r: np.ndarray, z: np.ndarray) -> None:
    """``z = (L L^T)^-1 r``: forward substitution on L's rows, then backward substitution on
    L^T's rows. The two blocks of ``factor.blocks`` (:class:`Matrix`) in parallel: forward
    blocks then separator, backward separator then blocks."""
    n = r.shape[0]
    blocks = factor.blocks
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
def _update(x: np.ndarray, r: np.ndarray, d: np.ndarray, q: np.ndarray, alpha: float) -> float:
    """``x += alpha d``, ``r -= alpha q``; returns |r|^2 (summed serially, as :func:`dot`)."""
    total = 0.0
    for i in range(x.shape[0]):
        x[i] += alpha * d[i]
        r[i] -= alpha * q[i]
        total += r[i] * r[i]
    return total


@njit(cache=True)
def _direction(d: np.ndarray, z: np.ndarray, beta: float) -> None:
    """``d = z + beta d``."""
    for i in range(d.shape[0]):
        d[i] = z[i] + beta * d[i]


@register_jitable
def preconditioned_cg(
    operator: LinearOperator,
    preconditioner: Preconditioner,
    b: np.ndarray,
    x: np.ndarray,
    tolerance: float,
    max_iterations: int,
) -> tuple[int, float]:
    """Preconditioned conjugate gradients for ``A x = b``, Eq. (F12), from the initial guess in
    ``x`` (overwritten by the solution); A is ``operator``, M ``preconditioner``. Stops when
    ``|b - A x| <= tolerance |b|``. Returns (iterations, relative residual).

    The one CG of the package. Compiled code calls it with the NamedTuples of
    :func:`linear_operator` and :func:`preconditioner` (:func:`conjugate_gradient`, the soft
    bell's implicit springs); Python calls it with any objects that have the methods (the
    deflated solver, whose coarse solve is SuperLU's): its vector work is in compiled kernels
    either way, with the same floating-point operations in the same order.
    """
    n = b.shape[0]
    norm_b = math.sqrt(dot(b, b))
    if n == 0:
        return 0, 0.0
    if norm_b == 0.0:
        x[:] = 0.0
        return 0, 0.0
    r = np.empty(n)
    operator.apply(x, r)
    r[:] = b - r
    z = np.empty(n)
    preconditioner.precondition(r, z)
    d = z.copy()
    q = np.empty(n)
    rz = dot(r, z)
    residual = math.sqrt(dot(r, r)) / norm_b
    iterations = 0
    while residual > tolerance and iterations < max_iterations:
        operator.apply(d, q)
        curvature = dot(d, q)
        if curvature == 0.0 or rz == 0.0:
            break  # the residual is exactly zero in exact arithmetic: nothing left to reduce
        residual = math.sqrt(_update(x, r, d, q, rz / curvature)) / norm_b
        iterations += 1
        if not math.isfinite(residual):
            break
        preconditioner.precondition(r, z)
        rz_new = dot(r, z)
        _direction(d, z, rz_new / rz)
        rz = rz_new
    return iterations, residual


@njit(cache=True)
def conjugate_gradient(
    matrix: Matrix,
    preconditioner: Factor | Identity,
    b: np.ndarray,
    x: np.ndarray,
    tolerance: float,
    max_iterations: int,
) -> tuple[int, float]:
    """:func:`preconditioned_cg` compiled for the PPE: preconditioned by the IC(0) factor
    (:func:`compact_factor`) or not at all (:class:`Identity`)."""
    return preconditioned_cg(matrix, preconditioner, b, x, tolerance, max_iterations)
