"""Compiled kernels of the mass-spring bell (paper §4.2.1, Eq. 6).

Springs are edges ``(a, b)`` of a fixed list; every particle gathers the forces of its own
springs through an adjacency list (``start``, ``edges``, ``signs``), so the sums are parallel,
free of write conflicts and bitwise reproducible (STYLE rule 4).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from jellysim.fluid.linalg import Identity, linear_operator, preconditioned_cg


@njit(cache=True, parallel=True)
def spring_tensions(
    position: np.ndarray,
    springs: np.ndarray,
    rest_length: np.ndarray,
    stiffness: np.ndarray,
    out: np.ndarray,
) -> None:
    """Per spring e = (a, b): ``f_e = k_e (|r_b - r_a| - L_e) (r_b - r_a) / |r_b - r_a|`` (N),
    the force on a (on b it is -f_e), into ``out`` (S, 3). Eq. (6) with ``r_ij = r_i - r_j``."""
    for e in prange(springs.shape[0]):
        a = springs[e, 0]
        b = springs[e, 1]
        d0 = position[b, 0] - position[a, 0]
        d1 = position[b, 1] - position[a, 1]
        d2 = position[b, 2] - position[a, 2]
        length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        scale = 0.0
        if length > 0.0:
            scale = stiffness[e] * (length - rest_length[e]) / length
        out[e, 0] = scale * d0
        out[e, 1] = scale * d1
        out[e, 2] = scale * d2


@njit(cache=True, parallel=True)
def gather_forces(
    tensions: np.ndarray,
    start: np.ndarray,
    edges: np.ndarray,
    signs: np.ndarray,
    out: np.ndarray,
) -> None:
    """``F_i = sum over i's springs of sign * f_e`` (N) into ``out`` (B, 3); ``signs`` is +1 where
    i is the spring's first end and -1 where it is the second."""
    for i in prange(start.shape[0] - 1):
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        for m in range(start[i], start[i + 1]):
            e = edges[m]
            s = signs[m]
            f0 += s * tensions[e, 0]
            f1 += s * tensions[e, 1]
            f2 += s * tensions[e, 2]
        out[i, 0] = f0
        out[i, 1] = f1
        out[i, 2] = f2


@njit(cache=True)
def _stiffness_product(
    springs: np.ndarray,
    normal: np.ndarray,
    along: np.ndarray,
    across: np.ndarray,
    start: np.ndarray,
    edges: np.ndarray,
    signs: np.ndarray,
    x: np.ndarray,
    work: np.ndarray,
    out: np.ndarray,
) -> None:
    """``out = K x`` (B, 3) for the springs' stiffness matrix K = dF/dr: per spring e = (a, b),
    ``w_e = along_e n (n . dx) + across_e (dx - n (n . dx))`` with ``dx = x_b - x_a``; the
    particles gather ``sign * w_e`` as in :func:`gather_forces`."""
    for e in range(springs.shape[0]):
        a = springs[e, 0]
        b = springs[e, 1]
        dot = 0.0
        for k in range(3):
            dot += normal[e, k] * (x[b, k] - x[a, k])
        for k in range(3):
            dx = x[b, k] - x[a, k]
            work[e, k] = along[e] * normal[e, k] * dot + across[e] * (dx - normal[e, k] * dot)
    for i in range(start.shape[0] - 1):
        for k in range(3):
            total = 0.0
            for m in range(start[i], start[i + 1]):
                total += signs[m] * work[edges[m], k]
            out[i, k] = total


@linear_operator
class _BackwardEuler(NamedTuple):
    """The matrix ``m I - dt^2 K`` (kg) of :func:`implicit_velocity_change` on a velocity change
    flattened to (3B,) m/s, giving (3B,) kg m/s; K as in :func:`_stiffness_product`, whose
    arrays these are."""

    springs: np.ndarray  # (S, 2) int
    normal: np.ndarray  # (S, 3)
    along: np.ndarray  # (S,) N/m
    across: np.ndarray  # (S,) N/m
    start: np.ndarray  # (B + 1,)
    edges: np.ndarray
    signs: np.ndarray
    mass: float  # kg
    h2: float  # dt^2, s2
    work: np.ndarray  # (S, 3) scratch
    product: np.ndarray  # (B, 3) scratch, K x

    def apply(self, x: np.ndarray, out: np.ndarray) -> None:
        """``out = m x - dt^2 K x``."""
        _stiffness_product(
            self.springs, self.normal, self.along, self.across, self.start, self.edges,
            self.signs, x.reshape((-1, 3)), self.work, self.product,
        )  # fmt: skip
        product = self.product.reshape(-1)
        for i in range(x.shape[0]):
            out[i] = self.mass * x[i] - self.h2 * product[i]


@njit(cache=True)
def implicit_velocity_change(
    position: np.ndarray,
    velocity: np.ndarray,
    springs: np.ndarray,
    rest_length: np.ndarray,
    stiffness: np.ndarray,
    start: np.ndarray,
    edges: np.ndarray,
    signs: np.ndarray,
    force: np.ndarray,
    mass: float,
    dt: float,
    tolerance: float,
    max_iterations: int,
    out: np.ndarray,
) -> tuple[int, float]:
    """Linearised backward Euler for the springs [Baraff & Witkin 1998]: the velocity change
    (B, 3) m/s over ``dt`` (s) solving ``(m I - dt^2 K) dv = dt (F + dt K v)``, with F
    ``force`` (B, 3) N at ``position``, v ``velocity``, m ``mass`` (kg) and K = dF/dr there,
    into ``out``; returns (CG iterations, relative residual) of
    :func:`jellysim.fluid.linalg.preconditioned_cg` (unpreconditioned).

    K's block for spring e, ``k (n n^T + max(1 - L / |d|, 0) (I - n n^T))`` (d = r_b - r_a,
    n = d / |d|), drops the compressed springs' negative transverse part so that the matrix
    stays symmetric positive definite (the usual fix for compressed springs); CG then converges
    for any dt.
    """
    n_springs = springs.shape[0]
    normal = np.zeros((n_springs, 3))
    along = np.zeros(n_springs)
    across = np.zeros(n_springs)
    for e in range(n_springs):
        a = springs[e, 0]
        b = springs[e, 1]
        length = 0.0
        for k in range(3):
            d = position[b, k] - position[a, k]
            normal[e, k] = d
            length += d * d
        length = math.sqrt(length)
        if length > 0.0:
            for k in range(3):
                normal[e, k] /= length
            along[e] = stiffness[e]
            across[e] = stiffness[e] * max(1.0 - rest_length[e] / length, 0.0)
    work = np.empty((n_springs, 3))
    product = np.empty_like(position)
    # right side and the explicit guess dv = dt F / m
    _stiffness_product(springs, normal, along, across, start, edges, signs, velocity, work, product)
    rhs = dt * (force + dt * product)
    for i in range(out.shape[0]):
        for k in range(3):
            out[i, k] = dt * force[i, k] / mass
    system = _BackwardEuler(
        springs, normal, along, across, start, edges, signs, mass, dt * dt, work, product
    )
    return preconditioned_cg(
        system, Identity(rhs.size), rhs.reshape(-1), out.reshape(-1), tolerance, max_iterations
    )
