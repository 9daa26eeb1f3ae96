"""Two-level deflated CG for the pressure Poisson equation: Jacobi on the particles, a coarse
problem on aggregates of particles.

The PPE of MPS is a Laplacian with a wide stencil (rows of ~50 entries in 2-D, ~120 in 3-D):
its slowest modes are smooth over the whole water body, and those are what make plain CG (and
IC(0)-preconditioned CG) take 100 and 40 iterations at 57,000 particles. Here the particles
are grouped by a lattice of cells ``coarse_cell`` l0 wide, Z (n, m) is 1 where row i lies in
aggregate a (piecewise-constant interpolation, as in aggregation multigrid), and the coarse
operator E = Z^T A Z (m, m) is factored exactly. The preconditioner is the "adapted deflation"
A-DEF2 of Tang, Nabben, Vuik & Erlangga (2009, J. Sci. Comput. 39, 340-370, Eq. 2.9):

    M^-1 r = y + Z E^-1 Z^T (r - A y),   y = D^-1 r,

with D the diagonal of A, started from ``x0 + Z E^-1 Z^T (b - A x0)`` so that every residual
is orthogonal to Z; in that subspace it is the balancing (BNN) preconditioner, symmetric and
positive definite. Every quantity is rebuilt each step from the current matrix (the rows
change with the free surface), which costs about one CG iteration.

Reductions are serial and the coarse solve is SuperLU's (one thread): results are bitwise the
same whatever the number of threads.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse
import scipy.sparse.linalg
from numba import njit, prange

from jellysim.fluid.kernels import FAST, Matrix, multiply


def aggregates(position: np.ndarray, origin: np.ndarray, size: float) -> tuple[np.ndarray, int]:
    """The aggregate of each row: rows whose positions ``position`` ((n, D) m) fall in the same
    cell of a lattice of cells ``size`` (m) wide from ``origin`` ((D,) m) share one. Aggregates
    are numbered in the order of their cells' linear index. Returns (key (n,) int64, m)."""
    if position.shape[0] == 0:
        return np.zeros(0, dtype=np.int64), 0
    cell = np.floor((position - origin) / size).astype(np.int64)
    cell -= cell.min(axis=0)
    linear = np.ravel_multi_index(tuple(cell.T), tuple(cell.max(axis=0) + 1))
    _, key = np.unique(linear, return_inverse=True)
    key = key.astype(np.int64).ravel()
    return key, int(key.max()) + 1


@njit(cache=True)
def _coarse_pattern(
    matrix: Matrix, key: np.ndarray, m: int, members_start: np.ndarray, members: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """E = Z^T A Z in CSR (sorted columns): E_ab = sum of A_ij over rows i in a, columns j in
    b. Two sweeps over each aggregate's rows: one finds the columns, one sums."""
    seen = np.full(m, -1, dtype=np.int64)
    indptr = np.zeros(m + 1, dtype=np.int64)
    for a in range(m):
        found = 0
        for t in range(members_start[a], members_start[a + 1]):
            i = members[t]
            for p in range(matrix.indptr[i], matrix.indptr[i + 1]):
                b = key[matrix.indices[p]]
                if seen[b] != a:
                    seen[b] = a
                    found += 1
        indptr[a + 1] = indptr[a] + found
    indices = np.empty(indptr[m], dtype=np.int64)
    data = np.zeros(indptr[m])
    slot = np.full(m, -1, dtype=np.int64)
    for a in range(m):
        end = indptr[a]
        for t in range(members_start[a], members_start[a + 1]):
            i = members[t]
            for p in range(matrix.indptr[i], matrix.indptr[i + 1]):
                b = key[matrix.indices[p]]
                if slot[b] < indptr[a]:  # first time in row a
                    slot[b] = end
                    indices[end] = b
                    end += 1
                data[slot[b]] += matrix.data[p]
        # sort row a's columns (short rows: insertion sort, carrying the values)
        for u in range(indptr[a] + 1, end):
            column = indices[u]
            value = data[u]
            v = u - 1
            while v >= indptr[a] and indices[v] > column:
                indices[v + 1] = indices[v]
                data[v + 1] = data[v]
                v -= 1
            indices[v + 1] = column
            data[v + 1] = value
    return indptr, indices, data


def coarse_operator(matrix: Matrix, key: np.ndarray, m: int) -> scipy.sparse.csc_matrix:
    """E = Z^T A Z (m, m) 1/m2 for the aggregates ``key`` ((n,) int64, of :func:`aggregates`).
    Symmetric, so its CSR arrays are also its CSC arrays."""
    order = np.argsort(key, kind="stable")
    members_start = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(np.bincount(key, minlength=m), out=members_start[1:])
    indptr, indices, data = _coarse_pattern(matrix, key, m, members_start, order)
    return scipy.sparse.csc_matrix((data, indices, indptr), shape=(m, m))


@njit(cache=True)
def restrict(key: np.ndarray, m: int, v: np.ndarray) -> np.ndarray:
    """Z^T v: the sum of ``v`` over each aggregate, (m,)."""
    out = np.zeros(m)
    for i in range(v.shape[0]):
        out[key[i]] += v[i]
    return out


@njit(cache=True, parallel=True, fastmath=FAST)
def _smooth(matrix: Matrix, inverse_diagonal: np.ndarray, r: np.ndarray, y: np.ndarray,
            t: np.ndarray) -> None:  # fmt: skip
    """``y = D^-1 r``, ``t = r - A y``."""
    n = r.shape[0]
    for i in prange(n):
        y[i] = inverse_diagonal[i] * r[i]
    multiply(matrix, y, t)
    for i in prange(n):
        t[i] = r[i] - t[i]


@njit(cache=True, parallel=True)
def _prolong_add(key: np.ndarray, coarse: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
    """``out = y + Z coarse``."""
    for i in prange(y.shape[0]):
        out[i] = y[i] + coarse[key[i]]


@njit(cache=True)
def _dot(a: np.ndarray, b: np.ndarray) -> float:
    total = 0.0
    for i in range(a.shape[0]):
        total += a[i] * b[i]
    return total


@njit(cache=True)
def _update(x: np.ndarray, r: np.ndarray, d: np.ndarray, q: np.ndarray, alpha: float) -> float:
    """``x += alpha d``, ``r -= alpha q``; returns |r|^2."""
    total = 0.0
    for i in range(x.shape[0]):
        x[i] += alpha * d[i]
        r[i] -= alpha * q[i]
        total += r[i] * r[i]
    return total


@njit(cache=True)
def _direction(d: np.ndarray, z: np.ndarray, beta: float) -> None:
    for i in range(d.shape[0]):
        d[i] = z[i] + beta * d[i]


class Deflation:
    """The coarse space of one PPE: aggregates, E's factor and D^-1 (built per solve)."""

    def __init__(self, matrix: Matrix, position: np.ndarray, origin: np.ndarray, size: float):
        self.matrix = matrix
        self.key, self.m = aggregates(position, origin, size)
        self.inverse_diagonal = 1.0 / matrix.data[matrix.diagonal]
        coarse = coarse_operator(matrix, self.key, self.m)
        self._lu = scipy.sparse.linalg.splu(coarse, permc_spec="MMD_AT_PLUS_A")

    def coarse_correction(self, v: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
        """``out = y + Z E^-1 Z^T v``."""
        coarse = self._lu.solve(restrict(self.key, self.m, v))
        _prolong_add(self.key, coarse, y, out)

    def precondition(self, r: np.ndarray, z: np.ndarray, y: np.ndarray, t: np.ndarray) -> None:
        """``z = M^-1 r`` (A-DEF2 with Jacobi); ``y``, ``t`` scratch (n,)."""
        _smooth(self.matrix, self.inverse_diagonal, r, y, t)
        self.coarse_correction(t, y, z)


def deflated_cg(
    matrix: Matrix,
    position: np.ndarray,
    origin: np.ndarray,
    size: float,
    b: np.ndarray,
    x: np.ndarray,
    tolerance: float,
    max_iterations: int,
) -> tuple[int, float]:
    """CG preconditioned by :class:`Deflation` for ``A x = b``, from the guess in ``x``
    (overwritten by the solution); rows at ``position`` ((n, D) m), aggregates ``size`` (m)
    wide on a lattice from ``origin``. Stops when ``|b - A x| <= tolerance |b|``, like
    :func:`jellysim.fluid.kernels.conjugate_gradient`. Returns (iterations, relative
    residual)."""
    n = b.shape[0]
    norm_b = math.sqrt(_dot(b, b))
    if n == 0:
        return 0, 0.0
    if norm_b == 0.0:
        x[:] = 0.0
        return 0, 0.0
    deflation = Deflation(matrix, position, origin, size)
    r = np.empty(n)
    multiply(matrix, x, r)
    r[:] = b - r
    deflation.coarse_correction(r, x.copy(), x)  # x0 + Z E^-1 Z^T r0: Z^T r = 0 from here on
    multiply(matrix, x, r)
    r[:] = b - r
    z, y, t, q = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    deflation.precondition(r, z, y, t)
    d = z.copy()
    rz = _dot(r, z)
    residual = math.sqrt(_dot(r, r)) / norm_b
    iterations = 0
    while residual > tolerance and iterations < max_iterations:
        multiply(matrix, d, q)
        curvature = _dot(d, q)
        if curvature == 0.0 or rz == 0.0:
            break  # the residual is exactly zero in exact arithmetic: nothing left to reduce
        residual = math.sqrt(_update(x, r, d, q, rz / curvature)) / norm_b
        iterations += 1
        if not math.isfinite(residual):
            break
        deflation.precondition(r, z, y, t)
        rz_new = _dot(r, z)
        _direction(d, z, rz_new / rz)
        rz = rz_new
    return iterations, residual
