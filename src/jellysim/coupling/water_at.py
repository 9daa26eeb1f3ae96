"""The simulated water's velocity at the tentacles (issue 26; docs/theory/soft-bell.md §8).

At a point x the water moves at the MPS weighted mean of the particles around it, with the weight
of the number density (Koshizuka & Oka 1996), w(r) = r_e / r - 1 for r < r_e:

    u(x) = sum_j w(|x_j - x|) u_j / sum_j w(|x_j - x|) * min(1, n(x) / (THIN n0)),
    n(x) = sum_j w(|x_j - x|)                                                        (S1)

over the live particles j that are not dummies: the water, the bell's particles (water in every
stage but the springs') and the walls (at rest, so the water slows towards them). n0 is the
number density of a particle inside the water. Where the water is thin, at the free surface or
outside it, n(x) falls below ``THIN`` n0 and the mean is faded to still water in proportion; a
point with no particle within r_e (out of the water, out of the tank) feels still water.

Two-way (``flow.two_way``): the drag impulse J_i that the water gave tentacle particle i over a
frame goes back to the water, equal and opposite, shared among the water and bell particles
within r_e with the same weights, normalised:

    Δp_j = -sum_i J_i w_ij / sum_k w_ik                                               (S2)

so the water receives exactly what the tentacles took (a point with no water particle within r_e
gives its reaction to nothing).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from jellysim.fluid.geometry import DUMMY
from jellysim.fluid.mps import MPSSolver

THIN = 0.5  # below this fraction of n0 the water counts as thin: its velocity fades to still


def _weights(
    points: np.ndarray, positions: np.ndarray, radius: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pairs (point row, particle col) closer than ``radius`` and their weights
    w = r_e / r - 1 (Eq. S1), through k-d trees of both sets. A point on a particle (distance 0)
    gets the weight ~1e9: that particle dominates."""
    empty = np.zeros(0, dtype=np.int64)
    if len(points) == 0 or len(positions) == 0:
        return empty, empty, np.zeros(0)
    near = cKDTree(points).sparse_distance_matrix(
        cKDTree(positions), radius, output_type="coo_matrix"
    )
    rows, cols, distance = near.row, near.col, near.data
    weight = radius / np.maximum(distance, 1e-9 * radius) - 1.0
    inside = distance < radius
    return rows[inside], cols[inside], weight[inside]


def water_velocity_at(
    points: np.ndarray,
    positions: np.ndarray,
    velocities: np.ndarray,
    radius: float,
    n0: float,
) -> np.ndarray:
    """Eq. (S1): the water's velocity (N, 3) m/s at ``points`` (N, 3) m from the particles at
    ``positions`` with ``velocities`` (M, 3), weight radius ``radius`` (r_e, m) and full number
    density ``n0``."""
    points = np.asarray(points, dtype=np.float64)
    out = np.zeros_like(points)
    rows, cols, weight = _weights(points, positions, radius)
    density = np.bincount(rows, weights=weight, minlength=len(points))
    for k in range(3):
        out[:, k] = np.bincount(rows, weights=weight * velocities[cols, k], minlength=len(points))
    fade = np.minimum(1.0, density / (THIN * n0))
    has = density > 0.0
    out[has] *= (fade[has] / density[has])[:, None]
    return out


def solver_water_velocity_at(solver: MPSSolver, points: np.ndarray) -> np.ndarray:
    """Eq. (S1) over ``solver``'s live particles that are not dummies, r_e and n0 of its number
    density."""
    use = solver.alive & (solver.kind != DUMMY)
    c = solver.constants
    return water_velocity_at(
        points, solver.position[use], solver.velocity[use], c.re_number_density, c.n0
    )


def spread_reaction(
    points: np.ndarray, impulses: np.ndarray, positions: np.ndarray, radius: float
) -> np.ndarray:
    """The reaction of the drag, Eq. (S2): each point's ``impulses`` (N, 3) N s, taken with the
    opposite sign, shared among the particles at ``positions`` (M, 3) within ``radius`` in
    proportion to the weight w(r) = r_e / r - 1 of Eq. (S1). Returns the momentum (M, 3) N s
    each particle receives; it sums to minus the impulses of the points that have a particle
    within ``radius`` (a point with none, out of the water, gives its reaction to nothing)."""
    out = np.zeros((len(positions), 3))
    rows, cols, weight = _weights(points, positions, radius)
    total = np.bincount(rows, weights=weight, minlength=len(points))
    share = weight / total[rows]
    for k in range(3):
        out[:, k] = -np.bincount(cols, weights=share * impulses[rows, k], minlength=len(positions))
    return out
