"""Compiled kernels of the mass-spring bell (paper §4.2.1, Eq. 6).

Springs are edges ``(a, b)`` of a fixed list; every particle gathers the forces of its own
springs through an adjacency list (``start``, ``edges``, ``signs``), so the sums are parallel,
free of write conflicts and bitwise reproducible (STYLE rule 4).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


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
