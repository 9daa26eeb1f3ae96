"""Two-level deflated CG for the pressure Poisson equation: Jacobi on the particles, a coarse
problem on aggregates of particles.

The PPE of MPS is a Laplacian with a wide stencil (rows of ~50 entries in 2-D, ~120 in 3-D):
its slowest modes are smooth over the whole water body, and those are what make plain CG (and
IC(0)-preconditioned CG) take 100 and 40 iterations at 57,000 particles. Here the particles
are grouped by a lattice of cells ``coarse_cell`` l0 wide, Z (n, m) is 1 where row i lies in
aggregate a (piecewise-constant interpolation, as in aggregation multigrid), and the coarse
operator E = Z^T A Z (m, m) is factored exactly. The preconditioner is the "adapted deflation"
A-DEF2 of Tang, Nabben, Vuik & Erlangga (2009, J. Sci. Comput. 39, 340-370):

    M^-1 r = y + Z E^-1 Z^T (r - A y),   y = D^-1 r,

with D the diagonal of A (``Z^T A y`` is taken as ``W y`` with W = Z^T A (m, n) summed once
per solve: about an eighth of a product with A in 3-D), started from
``x0 + Z E^-1 Z^T (b - A x0)`` so that every residual is orthogonal to Z; in that subspace it
is the balancing (BNN) preconditioner, symmetric and positive definite. Everything is rebuilt
each step from the current matrix (the rows change with the free surface), at the cost of five
to eight iterations.

Sums over all rows are serial, parallel loops are gathers (each writes its own row), and the
coarse solve is SuperLU's (one thread): results are bitwise the same whatever the number of
threads.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import scipy.sparse
import scipy.sparse.linalg
from numba import njit, prange

from jellysim.fluid.linalg import (
    Matrix,
    diagonal_values,
    dot,
    multiply,
    preconditioned_cg,
)

# fastmath as jellysim.fluid.linalg's FAST (contraction alone), written here: Numba compiles a
# kernel's flags into its cached machine code and compiles it again only when the kernel's own
# file changes, so flags imported from another module could go stale (a unit test holds the
# copies equal).
FAST = {"contract"}


def aggregates(position: np.ndarray, origin: np.ndarray, size: float) -> tuple[np.ndarray, int]:
    """The aggregate of each row: rows whose positions ``position`` ((n, D) m) fall in the same
    cell of a lattice of cells ``size`` (m) wide from ``origin`` ((D,) m) share one. Aggregates
    are numbered in the order of their cells' linear index. Returns (key (n,) int64, m)."""
    if position.shape[0] == 0:
        return np.zeros(0, dtype=np.int64), 0
    linear, shape = _linear_cells(position, origin, size)
    cells = math.prod(int(extent) for extent in shape)
    if min(shape) < 1 or cells >= 2**63:  # wrapped: a position not finite or a spread too wide
        raise ValueError(f"aggregates: rows spread over {cells} cells of {size} m")
    if cells <= _DENSE_CELLS * position.shape[0] + 4096:
        return _numbered_cells(linear, cells)
    _, key = np.unique(linear, return_inverse=True)  # a sparse spread: sort instead
    key = key.astype(np.int64).ravel()
    return key, int(key.max()) + 1


@njit(cache=True)
def _linear_cells(
    position: np.ndarray, origin: np.ndarray, size: float
) -> tuple[np.ndarray, np.ndarray]:
    """The lattice cell of each row of ``position`` ((n, D), n > 0) as NumPy's
    ``np.ravel_multi_index`` numbers it in the box of the occupied cells (C order: the last
    axis fastest), and the box's shape ((D,) int64): the cells ``floor((x - origin) / size)``
    and their bounds in one pass, then the numbers; serial (docs/performance.md, "Parallel
    regions a step"). Positions must be finite."""
    n, dim = position.shape
    cell = np.empty((n, dim), dtype=np.int64)
    lower = np.full(dim, np.iinfo(np.int64).max)
    upper = np.full(dim, np.iinfo(np.int64).min)
    for i in range(n):
        for k in range(dim):
            c = np.int64(math.floor((position[i, k] - origin[k]) / size))
            cell[i, k] = c
            lower[k] = min(lower[k], c)
            upper[k] = max(upper[k], c)
    shape = upper - lower + 1
    linear = np.empty(n, dtype=np.int64)
    for i in range(n):
        index = np.int64(0)
        for k in range(dim):
            index = index * shape[k] + cell[i, k] - lower[k]
        linear[i] = index
    return linear, shape


# aggregates() numbers the occupied cells through an array over the lattice's box while it has
# at most this many cells a row (one pass over rows and cells, no sort); beyond, np.unique.
_DENSE_CELLS = 16


@njit(cache=True)
def _numbered_cells(linear: np.ndarray, cells: int) -> tuple[np.ndarray, int]:
    """``np.unique(linear, return_inverse=True)``'s inverse for cells ``linear`` ((n,) int64 in
    ``[0, cells)``): each occupied cell numbered in the order of its index. Returns (key, m)."""
    number = np.full(cells, -1, dtype=np.int64)
    for i in range(linear.shape[0]):
        number[linear[i]] = 0
    m = 0
    for c in range(cells):
        if number[c] == 0:
            number[c] = m
            m += 1
    key = np.empty(linear.shape[0], dtype=np.int64)
    for i in range(linear.shape[0]):
        key[i] = number[linear[i]]
    return key, m


# Aggregates per chunk of the parallel loops that build W: each chunk keeps its own marker
# arrays over the n columns, and the rows come out the same whatever the chunks.
_CHUNK = 64


@njit(cache=True, parallel=True)
def _restricted_rows(
    matrix: Matrix, m: int, members_start: np.ndarray, members: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """W = Z^T A (m, n) in CSR: row a is the sum of A's rows over the members of aggregate a,
    its columns in the order first met. Two sweeps over chunks of aggregates in parallel: one
    counts the columns, one sums."""
    n = matrix.indptr.shape[0] - 1
    split = matrix.diagonal_value.shape[0] > 0
    chunks = (m + _CHUNK - 1) // _CHUNK
    indptr = np.zeros(m + 1, dtype=np.int64)
    for c in prange(chunks):
        seen = np.full(n, -1, dtype=np.int64)
        for a in range(c * _CHUNK, min((c + 1) * _CHUNK, m)):
            found = 0
            for t in range(members_start[a], members_start[a + 1]):
                i = members[t]
                for p in range(matrix.indptr[i], matrix.indptr[i + 1]):
                    j = matrix.indices[p]
                    if seen[j] != a:
                        seen[j] = a
                        found += 1
            indptr[a + 1] = found
    for a in range(m):
        indptr[a + 1] += indptr[a]
    indices = np.empty(indptr[m], dtype=np.int64)
    data = np.zeros(indptr[m])
    for c in prange(chunks):
        slot = np.full(n, -1, dtype=np.int64)
        for a in range(c * _CHUNK, min((c + 1) * _CHUNK, m)):
            end = indptr[a]
            for t in range(members_start[a], members_start[a + 1]):
                i = members[t]
                for p in range(matrix.indptr[i], matrix.indptr[i + 1]):
                    j = matrix.indices[p]
                    if slot[j] < indptr[a]:  # first time in row a (earlier rows' are lower)
                        slot[j] = end
                        indices[end] = j
                        end += 1
                    data[slot[j]] += matrix.data[p]
                if split:  # the diagonal in double (its slot in the row holds 0)
                    data[slot[i]] += matrix.diagonal_value[i]
    return indptr, indices, data


@njit(cache=True, parallel=True)
def _coarse_rows(
    indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, key: np.ndarray, m: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """E = W Z (m, m) in CSR with sorted columns, from W = Z^T A in CSR. Rows in chunks of
    aggregates in parallel (each chunk its own marker arrays, as :func:`_restricted_rows`):
    each row is summed in W's order whatever the threads."""
    chunks = (m + _CHUNK - 1) // _CHUNK
    coarse_indptr = np.zeros(m + 1, dtype=np.int64)
    for c in prange(chunks):
        seen = np.full(m, -1, dtype=np.int64)
        for a in range(c * _CHUNK, min((c + 1) * _CHUNK, m)):
            found = 0
            for p in range(indptr[a], indptr[a + 1]):
                b = key[indices[p]]
                if seen[b] != a:
                    seen[b] = a
                    found += 1
            coarse_indptr[a + 1] = found
    for a in range(m):
        coarse_indptr[a + 1] += coarse_indptr[a]
    coarse_indices = np.empty(coarse_indptr[m], dtype=np.int64)
    coarse_data = np.zeros(coarse_indptr[m])
    for c in prange(chunks):
        slot = np.full(m, -1, dtype=np.int64)
        for a in range(c * _CHUNK, min((c + 1) * _CHUNK, m)):
            first = coarse_indptr[a]
            end = first
            for p in range(indptr[a], indptr[a + 1]):
                b = key[indices[p]]
                if slot[b] < first:  # first time in row a (earlier rows' are lower)
                    slot[b] = end
                    coarse_indices[end] = b
                    end += 1
                coarse_data[slot[b]] += data[p]
            # sort row a's columns (short rows: insertion sort, carrying the values)
            for u in range(first + 1, end):
                column = coarse_indices[u]
                value = coarse_data[u]
                v = u - 1
                while v >= first and coarse_indices[v] > column:
                    coarse_indices[v + 1] = coarse_indices[v]
                    coarse_data[v + 1] = coarse_data[v]
                    v -= 1
                coarse_indices[v + 1] = column
                coarse_data[v + 1] = value
    return coarse_indptr, coarse_indices, coarse_data


class Restriction(NamedTuple):
    """W = Z^T A (m, n) in CSR (1/m2), the rows of A summed over each aggregate."""

    indptr: np.ndarray  # (m + 1,) int64
    indices: np.ndarray  # (nnz_W,) int64
    data: np.ndarray  # (nnz_W,) float64


def restricted_operator(matrix: Matrix, key: np.ndarray, m: int) -> Restriction:
    """W = Z^T A for the aggregates ``key`` ((n,) int64, of :func:`aggregates`)."""
    members_start, members = _members(key, m)
    return Restriction(*_restricted_rows(matrix, m, members_start, members))


@njit(cache=True)
def _members(key: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """The rows of each aggregate, by a counting sort of ``key`` ((n,) in ``[0, m)``): (start
    (m + 1,), members (n,)), aggregate a's rows ``members[start[a]:start[a + 1]]`` in increasing
    order (``np.argsort(key, kind="stable")``'s order, in one pass)."""
    start = np.zeros(m + 1, dtype=np.int64)
    for i in range(key.shape[0]):
        start[key[i] + 1] += 1
    for a in range(m):
        start[a + 1] += start[a]
    cursor = start[:m].copy()
    members = np.empty(key.shape[0], dtype=np.int64)
    for i in range(key.shape[0]):
        members[cursor[key[i]]] = i
        cursor[key[i]] += 1
    return start, members


def coarse_operator(restriction: Restriction, key: np.ndarray, m: int) -> scipy.sparse.csc_matrix:
    """E = Z^T A Z = W Z (m, m) 1/m2. Symmetric, so its CSR arrays are also its CSC arrays."""
    indptr, indices, data = _coarse_rows(*restriction, key, m)
    return scipy.sparse.csc_matrix((data, indices, indptr), shape=(m, m))


@njit(cache=True)
def restrict(key: np.ndarray, m: int, v: np.ndarray) -> np.ndarray:
    """Z^T v: the sum of ``v`` over each aggregate, (m,)."""
    out = np.zeros(m)
    for i in range(v.shape[0]):
        out[key[i]] += v[i]
    return out


@njit(cache=True, parallel=True, fastmath=FAST)
def _smooth(
    restriction: Restriction,
    key: np.ndarray,
    inverse_diagonal: np.ndarray,
    r: np.ndarray,
    y: np.ndarray,
) -> np.ndarray:
    """``y = D^-1 r``; returns ``Z^T (r - A y) = Z^T r - W y`` (m,)."""
    n = r.shape[0]
    m = restriction.indptr.shape[0] - 1
    for i in prange(n):
        y[i] = inverse_diagonal[i] * r[i]
    out = restrict(key, m, r)
    for a in prange(m):
        total = 0.0
        for p in range(restriction.indptr[a], restriction.indptr[a + 1]):
            total += restriction.data[p] * y[restriction.indices[p]]
        out[a] -= total
    return out


@njit(cache=True, parallel=True)
def _prolong_add(key: np.ndarray, coarse: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
    """``out = y + Z coarse``."""
    for i in prange(y.shape[0]):
        out[i] = y[i] + coarse[key[i]]


class Deflation:
    """The coarse space of one PPE: aggregates, W = Z^T A, E's factor and D^-1 (built per
    solve)."""

    def __init__(self, matrix: Matrix, position: np.ndarray, origin: np.ndarray, size: float):
        self.key, self.m = aggregates(position, origin, size)
        self.inverse_diagonal = 1.0 / diagonal_values(matrix)
        self._smoothed = np.empty(matrix.diagonal.shape[0])  # y of :meth:`precondition`
        self.restriction = restricted_operator(matrix, self.key, self.m)
        coarse = coarse_operator(self.restriction, self.key, self.m)
        # E is symmetric positive definite: SymmetricMode takes the diagonal pivots of the
        # symmetric ordering, 3x faster to factor than the default (9 against 26-30 ms for the
        # 1,298 aggregates of the benchmark's 3-D tank)
        self._lu = scipy.sparse.linalg.splu(
            coarse, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True}
        )

    def coarse_correction(self, v: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
        """``out = y + Z E^-1 Z^T v``."""
        coarse = self._lu.solve(restrict(self.key, self.m, v))
        _prolong_add(self.key, coarse, y, out)

    def precondition(self, r: np.ndarray, z: np.ndarray) -> None:
        """``z = M^-1 r = y + Z E^-1 Z^T (r - A y)``, ``y = D^-1 r`` (A-DEF2 with Jacobi; one
        product with W instead of A)."""
        y = self._smoothed
        coarse = self._lu.solve(_smooth(self.restriction, self.key, self.inverse_diagonal, r, y))
        _prolong_add(self.key, coarse, y, z)


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
    wide on a lattice from ``origin``. The iterations are :func:`jellysim.fluid.linalg.
    preconditioned_cg`'s, from ``x0 + Z E^-1 Z^T (b - A x0)``. Returns (iterations, relative
    residual)."""
    n = b.shape[0]
    if n == 0 or dot(b, b) == 0.0:  # nothing to solve, as preconditioned_cg finds: no E to build
        x[:] = 0.0
        return 0, 0.0
    deflation = Deflation(matrix, position, origin, size)
    r = np.empty(n)
    multiply(matrix, x, r)
    r[:] = b - r
    deflation.coarse_correction(r, x.copy(), x)  # x0 + Z E^-1 Z^T r0: Z^T r = 0 from here on
    return preconditioned_cg(matrix, deflation, b, x, tolerance, max_iterations)
