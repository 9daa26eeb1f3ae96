"""Compiled kernels of the MPS method [Koshizuka & Oka 1996] (equations in docs/theory/fluid.md).

Arrays: positions and velocities ``(N, D)`` float64 in m and m/s (D = 2 or 3, the same kernels
for both), pressure ``(N,)`` Pa, number density ``(N,)`` dimensionless, ``alive (N,)`` bool,
``kind (N,)`` int8 (FLUID, WALL, DUMMY of :mod:`jellysim.fluid.geometry`). Dead particles take
part in nothing.

Every parallel loop is a gather: particle i reads its neighbours and writes only its own row, so
results are bitwise identical whatever the number of threads. The neighbour search is
:mod:`jellysim.fluid.neighbours`, the pressure Poisson equation :mod:`jellysim.fluid.poisson`.

Weight, Eq. (F1): ``w(r) = r_e / r - 1`` for ``r < r_e``, else 0.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from jellysim.fluid.geometry import DUMMY, FLUID
from jellysim.fluid.neighbours import Neighbours

# fastmath as jellysim.fluid.linalg's FAST (contraction alone), written here: Numba compiles a
# kernel's flags into its cached machine code and compiles it again only when the kernel's own
# file changes, so flags imported from another module could go stale (a unit test holds the
# copies equal).
FAST = {"contract"}


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


@njit(cache=True)
def weight(r: float, re: float) -> float:
    """Eq. (F1): ``w = r_e / r - 1`` for ``0 < r < r_e``, else 0 (dimensionless)."""
    if r < re:
        return re / r - 1.0
    return 0.0


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


@njit(cache=True, parallel=True)  # no fastmath: it would drop the finiteness tests
def commit_step(
    position: np.ndarray,
    velocity: np.ndarray,
    new_position: np.ndarray,
    new_velocity: np.ndarray,
    pressure: np.ndarray,
    kind: np.ndarray,
    alive: np.ndarray,
    domain_min: np.ndarray,
    domain_max: np.ndarray,
) -> int:
    """The step's corrected state into ``position`` and ``velocity``; then live fluid particles
    outside [``domain_min``, ``domain_max``] or no longer finite (position or velocity) die:
    ``alive`` False, velocity and pressure 0. Returns the particles not alive after it. One
    parallel pass (it was serial NumPy, the part of a step that scaled least on 16 threads,
    docs/performance.md)."""
    n, dim = position.shape
    dead = 0
    for i in prange(n):
        keep = True
        for d in range(dim):
            x = new_position[i, d]
            v = new_velocity[i, d]
            position[i, d] = x
            velocity[i, d] = v
            if not (np.isfinite(x) and np.isfinite(v) and domain_min[d] <= x <= domain_max[d]):
                keep = False
        if not keep and alive[i] and kind[i] == FLUID:
            alive[i] = False
            for d in range(dim):
                velocity[i, d] = 0.0
            pressure[i] = 0.0
        if not alive[i]:
            dead += 1
    return dead


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
    wide: Neighbours | None = None,
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
    radius, ``-sum_j (r_j - r_i) w(r, r_e,lap) / r``, taken over ``wide`` (a list that reaches
    that radius) where ``neighbours`` holds only the entries within r_e,grad
    (:meth:`~jellysim.fluid.mps.MPSSolver.near`). Other kinds are copied unchanged.
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
            if wide is None:
                _surface_repulsion(i, position, pressure, kind, neighbours, constants, gradient)
            else:
                _surface_repulsion(i, position, pressure, kind, wide, constants, gradient)
        for k in range(dim):
            du = coefficient * gradient[k]
            out_velocity[i, k] += du
            out_position[i, k] += dt * du


@njit(cache=True, parallel=True, fastmath=FAST)
def conservative_pressure_correction(
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
) -> None:
    """The pair-wise antisymmetric gradient, Eq. (F10c) [Khayyer & Gotoh 2008], and the
    correction of fluid particles, Eq. (F13):

    ``grad p_i = (D / n0) sum_j ((p_i + p_j) - (p_min,i + p_min,j)) / r_ij^2 (r_j - r_i) w``,
    with ``p_min,i`` the least pressure among i and its fluid and wall neighbours within
    r_e,grad (a particle without a neighbour-list row: its own pressure); dummies are ignored.
    The coefficient of each pair is symmetric in i and j and ``r_j - r_i`` is not, so two fluid
    particles (equal masses) receive equal and opposite impulses: the pressure leaves the
    water's momentum unchanged but for what walls give it. ``u_i += -dt grad p_i / rho``,
    ``r_i += dt`` times that change; other kinds are copied unchanged.
    """
    n, dim = position.shape
    re = constants.re_gradient
    coefficient = -dt * dim / (constants.n0_gradient * constants.density)
    lowest = np.empty(n)
    for i in prange(n):
        for k in range(dim):
            out_velocity[i, k] = velocity[i, k]
            out_position[i, k] = position[i, k]
        least = pressure[i]
        if alive[i]:
            for m in range(neighbours.start[i], neighbours.start[i + 1]):
                j = neighbours.indices[m]
                if neighbours.distance[m] < re and kind[j] != DUMMY and alive[j]:
                    least = min(least, pressure[j])
        lowest[i] = least
    active = _fluid_rows(kind, alive)
    for a in prange(active.shape[0]):
        i = active[a]
        gradient = np.zeros(dim)
        for m in range(neighbours.start[i], neighbours.start[i + 1]):
            j = neighbours.indices[m]
            r = neighbours.distance[m]
            if r >= re or kind[j] == DUMMY or not alive[j]:
                continue
            excess = (pressure[i] + pressure[j]) - (lowest[i] + lowest[j])
            scale = excess / (r * r) * weight(r, re)
            for k in range(dim):
                gradient[k] += scale * (position[j, k] - position[i, k])
        for k in range(dim):
            du = coefficient * gradient[k]
            out_velocity[i, k] += du
            out_position[i, k] += dt * du
