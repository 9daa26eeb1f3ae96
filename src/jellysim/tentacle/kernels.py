"""Compiled kernels of the tentacle model (paper §4.1; equations in docs/theory/tentacle.md).

A tentacle is a chain of P particles at spacing d, root first. Arrays are float64:
positions and velocities ``(T, P, 3)`` in m and m/s for T chains. The root (particle 0) is
prescribed; particles 1..P-1 are free. The step, per chain and substep dt (Eq. T6-T9):

1. drag gain ``k_i`` from the relative velocity at the start of the step (Eq. T5),
2. one backward-Euler step of bending (Eq. T2) and drag, constrained by the segment lengths
   linearised at the start of the step: the saddle-point (KKT) system
   ``[A  J^T; J  0] [x; lambda] = [M (x + dt v) + dt K_d x + dt^2 (f + K_d u); d]`` with
   ``A = M + dt K_d + dt^2 c K`` and f the buoyant weight plus, for a chain with a rest shape,
   the rest shape's force at the start of the step (Eq. T13), interleaved per particle into a
   band of half-width 8 and solved by a banded LDL^T factorisation in O(P) (Eq. T7);
   re-linearised at the new iterate while a length is off by more than 1e-3,
3. exact projection onto ``|x_{i+1} - x_i| = d`` by Newton iterations of the fast projection
   on a tridiagonal system, O(P) each; it only removes the linearisation's second-order error
   (Eq. T8),
4. where the chain has an obstacle (the bell's shell, ``bell.tentacle_contact``): the particles
   inside it put back on its surface and the lengths projected again together with the wall's
   tangent plane at each of them, in rounds (Eq. T15-T17),
5. ``v = (x_new - x_old) / dt`` (Eq. T9).

Solving bending and the constraints together keeps the scheme consistent at any dt: at rest its
fixed point is the exact static equilibrium of the discrete chain.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from jellysim.tentacle.contact import Obstacle, push_out
from jellysim.tentacle.lanes import BAND, LANES, _band_ldlt_solve_lanes

REYNOLDS_STOKES = 1.0  # below: Stokes drag 3 pi mu d u (Eq. T4, first branch)
REYNOLDS_HOLD = 1.0e4  # above: the drag coefficient is held at its value here (Eq. T4)
DRAG_SPHERE = 0  # tentacles.drag = "sphere": the paper's law, Eq. (T4-T5)
DRAG_SLENDER = 1  # tentacles.drag = "slender": normal and tangential drag, Eq. (T14)


class ChainModel(NamedTuple):
    """Topology and lumped coefficients shared by every chain (built once, never mutated).

    ``mass``, ``inverse_mass``, ``volume``: ``(P,)`` kg, 1/kg, m3 (root inverse mass 0).
    ``stiffness_diag``, ``stiffness_off1``, ``stiffness_off2``: ``(P-1,)`` bands of the
    dimensionless bending matrix K over the free particles (force = -c K x).
    ``root_coupling``: ``(2,)`` K entries coupling free particles 1 and 2 to the root.
    ``free_root``: the root is a free particle too (a detached chain; bands then span all P).
    """

    mass: np.ndarray
    inverse_mass: np.ndarray
    volume: np.ndarray
    stiffness_diag: np.ndarray
    stiffness_off1: np.ndarray
    stiffness_off2: np.ndarray
    root_coupling: np.ndarray
    bending_stiffness: float  # c = 48 E I / L^3, N/m (Eq. T2)
    clamped: bool
    spacing: float  # d, m
    free_root: bool
    drag_law: int = 0  # DRAG_SPHERE: the paper's sphere per particle; DRAG_SLENDER: Eq. (T14)
    normal_drag: float = 0.0  # C_n of the slender law, on the projected area d l
    tangential_drag: float = 0.0  # C_t of the slender law, on the wetted area pi d l


class Medium(NamedTuple):
    """The water and the tentacle material."""

    density: float  # rho_w, kg/m3
    viscosity: float  # mu, Pa s
    gravity: np.ndarray  # (3,) m/s2
    tentacle_density: float  # rho_t, kg/m3


@njit(cache=True, inline="always")
def drag_coefficient(reynolds: float) -> float:
    """Sphere drag coefficient of the paper, Eq. (T4) [Hirato & Kawaguchi Eq. 4].

    ``C_R = 24 / Re`` for Re < 1; ``(0.55 + 4.8 / sqrt(Re))^2`` for 1 <= Re <= 1e4; held at its
    value at Re = 1e4 above. The law jumps from 24 to 28.6 at Re = 1, as the paper writes it.
    """
    if reynolds < REYNOLDS_STOKES:
        return 24.0 / reynolds
    re = min(reynolds, REYNOLDS_HOLD)
    root = 0.55 + 4.8 / math.sqrt(re)
    return root * root


@njit(cache=True, inline="always")
def drag_gain(speed: float, diameter: float, density: float, viscosity: float) -> float:
    """Gain k (kg/s) with drag force ``F = k u_r`` on a sphere, Eq. (T5).

    ``F = C_R(Re) (rho/2) |u_r| u_r (pi d^2 / 4)``, ``Re = |u_r| d rho / mu``; below Re = 1 this is
    written as Stokes' ``3 pi mu d u_r`` so that it stays finite at rest.
    """
    reynolds = speed * diameter * density / viscosity
    if reynolds < REYNOLDS_STOKES:
        return 3.0 * math.pi * viscosity * diameter
    area = 0.25 * math.pi * diameter * diameter
    return drag_coefficient(reynolds) * 0.5 * density * speed * area


@njit(cache=True, inline="always")
def slender_drag_gains(
    tangent: np.ndarray,
    relative: np.ndarray,
    diameter: float,
    length: float,
    density: float,
    normal_drag: float,
    tangential_drag: float,
) -> tuple[float, float]:
    """Gains (kg/s) of the slender law, Eq. (T14), on a piece of chain of ``length`` along the
    unit ``tangent`` moving at ``relative`` (water minus chain, m/s): the force is
    ``k_n w_n + k_t w_t`` with w_t = (w . t) t and w_n = w - w_t (the independence principle),
    ``k_n = (rho/2) C_n d l |w_n|`` and ``k_t = (rho/2) C_t pi d l |w_t|``."""
    along = relative[0] * tangent[0] + relative[1] * tangent[1] + relative[2] * tangent[2]
    n0 = relative[0] - along * tangent[0]
    n1 = relative[1] - along * tangent[1]
    n2 = relative[2] - along * tangent[2]
    across = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    half = 0.5 * density * diameter * length
    return half * normal_drag * across, half * tangential_drag * math.pi * abs(along)


@njit(cache=True)
def bending_energy(x: np.ndarray, c: float, clamped: bool, clamp_direction: np.ndarray) -> float:
    """Discrete bending energy (J) of one chain ``x`` (P, 3), Eq. (T1).

    ``E = (c/8) sum_{i=1}^{P-2} |x_{i-1} - 2 x_i + x_{i+1}|^2`` plus, for a clamped root with
    direction t, ``(c/4) |(I - t t^T)(x_1 - x_0)|^2`` (a mirror ghost particle, half weight).
    """
    energy = 0.0
    for i in range(1, x.shape[0] - 1):
        for k in range(3):
            s = x[i - 1, k] - 2.0 * x[i, k] + x[i + 1, k]
            energy += 0.125 * c * s * s
    if clamped:
        e = x[1] - x[0]
        along = e[0] * clamp_direction[0] + e[1] * clamp_direction[1] + e[2] * clamp_direction[2]
        for k in range(3):
            p = e[k] - along * clamp_direction[k]
            energy += 0.25 * c * p * p
    return energy


@njit(cache=True)
def bending_forces(
    x: np.ndarray, c: float, clamped: bool, clamp_direction: np.ndarray, out: np.ndarray
) -> None:
    """Bending force (N) on every particle of one chain, Eq. (T2) [paper Eq. 1-2], into ``out``.

    ``h_i = x_i - (x_{i-1} + x_{i+1}) / 2``, ``P_i = c h_i``: ``-P_i`` on i and ``+P_i / 2`` on
    i - 1 and i + 1; plus the clamp term's force. Equals minus the gradient of
    :func:`bending_energy`.
    """
    out[:] = 0.0
    for i in range(1, x.shape[0] - 1):
        for k in range(3):
            p = c * (x[i, k] - 0.5 * (x[i - 1, k] + x[i + 1, k]))
            out[i, k] -= p
            out[i - 1, k] += 0.5 * p
            out[i + 1, k] += 0.5 * p
    if clamped:
        e = x[1] - x[0]
        along = e[0] * clamp_direction[0] + e[1] * clamp_direction[1] + e[2] * clamp_direction[2]
        for k in range(3):
            f = 0.5 * c * (e[k] - along * clamp_direction[k])
            out[1, k] -= f
            out[0, k] += f


@njit(cache=True)
def _transport(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> tuple[float, float, float]:
    """Parallel transport of ``u`` from the unit tangent ``a`` to the unit tangent ``b``
    (Eq. T11): the rotation about ``a x b`` that takes a to b, applied to u."""
    c0 = a[1] * b[2] - a[2] * b[1]
    c1 = a[2] * b[0] - a[0] * b[2]
    c2 = a[0] * b[1] - a[1] * b[0]
    cos = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    w = (c0 * u[0] + c1 * u[1] + c2 * u[2]) / (1.0 + cos)
    return (
        cos * u[0] + c1 * u[2] - c2 * u[1] + w * c0,
        cos * u[1] + c2 * u[0] - c0 * u[2] + w * c1,
        cos * u[2] + c0 * u[1] - c1 * u[0] + w * c2,
    )


@njit(cache=True, inline="always")
def _curl_frames(
    x: np.ndarray,
    clamp_direction: np.ndarray,
    curl_normal: np.ndarray,
    rest: np.ndarray,
    work: np.ndarray,
) -> None:
    """The chain's parallel-transported frames and rest second differences (Eq. T11-T12).

    Fills ``work`` (6, P, 3): row 0 the unit tangents t_j of the segments j = 0..P-2, row 1 the
    transported normals n_j, row 2 at node i = 1..P-2 the rest second difference
    ``g_i = F_{i-1} r_i`` (m), row 3 the second differences ``x_{i-1} - 2 x_i + x_{i+1}``,
    ``work[4, j, 0]`` the segment lengths and ``work[4, j, 1]`` their inverses, and row 5 the
    rotation vectors ``q_j = t_{j-1} x t_j / (1 + t_{j-1} . t_j)`` (t_{-1} the clamp direction).

    The transport of Eq. (T11), ``n_j = cos n_{j-1} + c x n_{j-1} + (c . n_{j-1}) q_j`` with
    ``c = t_{j-1} x t_j`` and ``cos = t_{j-1} . t_j``, is :func:`_transport` with its division
    taken once per segment (into q_j), outside the recurrence from one normal to the next.
    """
    n_particles = x.shape[0]
    tangents = work[0]
    normals = work[1]
    q = work[5]
    for j in range(n_particles - 1):
        length = 0.0
        for k in range(3):
            e = x[j + 1, k] - x[j, k]
            tangents[j, k] = e
            length += e * e
        length = math.sqrt(length)
        inverse = 1.0 / length
        work[4, j, 0] = length
        work[4, j, 1] = inverse
        for k in range(3):
            tangents[j, k] *= inverse
    u0, u1, u2 = curl_normal[0], curl_normal[1], curl_normal[2]
    for j in range(n_particles - 1):
        a = clamp_direction if j == 0 else tangents[j - 1]
        b = tangents[j]
        c0 = a[1] * b[2] - a[2] * b[1]
        c1 = a[2] * b[0] - a[0] * b[2]
        c2 = a[0] * b[1] - a[1] * b[0]
        cos = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
        inverse = 1.0 / (1.0 + cos)
        q0, q1, q2 = c0 * inverse, c1 * inverse, c2 * inverse
        q[j, 0], q[j, 1], q[j, 2] = q0, q1, q2
        w = c0 * u0 + c1 * u1 + c2 * u2
        n0 = cos * u0 + c1 * u2 - c2 * u1 + w * q0
        n1 = cos * u1 + c2 * u0 - c0 * u2 + w * q1
        n2 = cos * u2 + c0 * u1 - c1 * u0 + w * q2
        normals[j, 0], normals[j, 1], normals[j, 2] = n0, n1, n2
        u0, u1, u2 = n0, n1, n2
    for i in range(1, n_particles - 1):
        t = tangents[i - 1]
        n = normals[i - 1]
        b0 = t[1] * n[2] - t[2] * n[1]
        b1 = t[2] * n[0] - t[0] * n[2]
        b2 = t[0] * n[1] - t[1] * n[0]
        r = rest[i]
        work[2, i, 0] = r[0] * t[0] + r[1] * n[0] + r[2] * b0
        work[2, i, 1] = r[0] * t[1] + r[1] * n[1] + r[2] * b1
        work[2, i, 2] = r[0] * t[2] + r[1] * n[2] + r[2] * b2
        for k in range(3):
            work[3, i, k] = x[i - 1, k] - 2.0 * x[i, k] + x[i + 1, k]


@njit(cache=True)
def curl_energy(
    x: np.ndarray,
    c: float,
    clamp_direction: np.ndarray,
    curl_normal: np.ndarray,
    rest: np.ndarray,
    work: np.ndarray,
) -> float:
    """What a rest shape adds to the bending energy (J) of one chain ``x`` (P, 3), Eq. (T12).

    ``sum_i (c/8) (|x_{i-1} - 2 x_i + x_{i+1} - g_i|^2 - |x_{i-1} - 2 x_i + x_{i+1}|^2)``: with
    :func:`bending_energy` the energy ``(c/8) sum |Delta^2 x_i - g_i|^2`` of a chain whose rest
    second differences are ``g_i = F_{i-1} r_i``, ``rest`` (P, 3) the components r_i (m) in the
    frame F_{i-1} = (t, n, t x n) parallel-transported from the root frame (``clamp_direction``,
    ``curl_normal``, unit and perpendicular) along the segments. ``work`` (6, P, 3) is scratch.
    """
    _curl_frames(x, clamp_direction, curl_normal, rest, work)
    energy = 0.0
    for i in range(1, x.shape[0] - 1):
        for k in range(3):
            g = work[2, i, k]
            energy += 0.125 * c * g * g - 0.25 * c * work[3, i, k] * g
    return energy


@njit(cache=True, inline="always")
def curl_forces(
    x: np.ndarray,
    c: float,
    clamp_direction: np.ndarray,
    curl_normal: np.ndarray,
    rest: np.ndarray,
    work: np.ndarray,
    out: np.ndarray,
) -> None:
    """Force (N) of the rest shape on every particle of one chain, minus the gradient of
    :func:`curl_energy`, into ``out`` (P, 3), Eq. (T13). O(P).

    ``(c/4)`` times the gradient of ``W = sum_i Delta^2 x_i . g_i``: the direct part
    ``g_{i-1} - 2 g_i + g_{i+1}`` and the part through the frames. A frame turned by an
    infinitesimal rotation omega_j changes W by ``omega_j . tau_j``, ``tau_j = g_{j+1} x
    Delta^2 x_{j+1}``; omega_j is ``t_j x delta t_j`` across the segment plus the twist
    ``psi_j = -sum_{k<=j} q_k . (delta t_{k-1} + delta t_k)`` along it, with
    ``q_k = t_{k-1} x t_k / (1 + t_{k-1} . t_k)`` (t_{-1} the fixed clamp direction). Gathered per
    segment: ``a_j = tau_j x t_j - S_j q_j - S_{j+1} q_{j+1}``, S_k the sum of ``t_j . tau_j`` over
    j >= k, and ``dW/de_j = (I - t_j t_j^T) a_j / |e_j|``. ``work`` (6, P, 3) is scratch.
    """
    n_particles = x.shape[0]
    n_segments = n_particles - 1
    _curl_frames(x, clamp_direction, curl_normal, rest, work)
    tangents = work[0]
    g = work[2]
    torque = work[1]  # the normals are not needed any more: tau_j (row 1)
    q = work[5]  # q_j, from _curl_frames
    quarter = 0.25 * c
    out[:] = 0.0
    for i in range(1, n_particles - 1):
        for k in range(3):
            out[i - 1, k] += quarter * g[i, k]
            out[i, k] -= 2.0 * quarter * g[i, k]
            out[i + 1, k] += quarter * g[i, k]
    for j in range(n_segments):
        if j + 1 < n_particles - 1:
            s0 = work[3, j + 1, 0]
            s1 = work[3, j + 1, 1]
            s2 = work[3, j + 1, 2]
            gg = g[j + 1]
            torque[j, 0] = gg[1] * s2 - gg[2] * s1
            torque[j, 1] = gg[2] * s0 - gg[0] * s2
            torque[j, 2] = gg[0] * s1 - gg[1] * s0
        else:
            torque[j, 0] = 0.0
            torque[j, 1] = 0.0
            torque[j, 2] = 0.0
    suffix = 0.0  # S_{j+1}
    for j in range(n_segments - 1, -1, -1):
        t = tangents[j]
        tau = torque[j]
        later = suffix
        suffix += t[0] * tau[0] + t[1] * tau[1] + t[2] * tau[2]
        a0 = tau[1] * t[2] - tau[2] * t[1] - suffix * q[j, 0]
        a1 = tau[2] * t[0] - tau[0] * t[2] - suffix * q[j, 1]
        a2 = tau[0] * t[1] - tau[1] * t[0] - suffix * q[j, 2]
        if j + 1 < n_segments:
            a0 -= later * q[j + 1, 0]
            a1 -= later * q[j + 1, 1]
            a2 -= later * q[j + 1, 2]
        along = a0 * t[0] + a1 * t[1] + a2 * t[2]
        scale = quarter * work[4, j, 1]
        f0 = scale * (a0 - along * t[0])
        f1 = scale * (a1 - along * t[1])
        f2 = scale * (a2 - along * t[2])
        out[j + 1, 0] += f0
        out[j + 1, 1] += f1
        out[j + 1, 2] += f2
        out[j, 0] -= f0
        out[j, 1] -= f1
        out[j, 2] -= f2


@njit(cache=True)
def rest_shape_positions(
    root: np.ndarray,
    clamp_direction: np.ndarray,
    curl_normal: np.ndarray,
    rest: np.ndarray,
    spacing: float,
    out: np.ndarray,
) -> None:
    """The chain in its rest shape, into ``out`` (P, 3) m: the zero of :func:`curl_energy` plus
    :func:`bending_energy`, Eq. (T10, T12). The first segment leaves the root along the clamp
    direction; then ``e_i = e_{i-1} + g_i`` with g_i in the frame transported along the chain as
    :func:`curl_forces` transports it, so the shape is the discrete energy's exact minimum."""
    for k in range(3):
        out[0, k] = root[k]
        out[1, k] = root[k] + spacing * clamp_direction[k]
    tangent = clamp_direction.copy()
    normal = curl_normal.copy()
    edge = spacing * clamp_direction
    for i in range(1, out.shape[0] - 1):
        r = rest[i]
        binormal = np.cross(tangent, normal)
        for k in range(3):
            edge[k] += r[0] * tangent[k] + r[1] * normal[k] + r[2] * binormal[k]
        length = math.sqrt(edge[0] ** 2 + edge[1] ** 2 + edge[2] ** 2)
        new_tangent = edge / length
        n0, n1, n2 = _transport(tangent, new_tangent, normal)
        normal[0], normal[1], normal[2] = n0, n1, n2
        tangent = new_tangent
        for k in range(3):
            out[i + 1, k] = out[i, k] + edge[k]


KKT_BLOCK = 4  # unknowns per particle in the saddle-point system: x, y, z and one multiplier
KKT_HALF_BANDWIDTH = 8  # x_i couples to the same component of x_{i+2}: 2 blocks
KKT_PADDING = KKT_HALF_BANDWIDTH  # zero rows before and after a system in its band storage
assert BAND == KKT_HALF_BANDWIDTH  # the lanes' solve (lanes.py) is compiled for this band


# fastmath limited to contraction (fused multiply-adds): no reassociation, so the order of every
# sum is the one written here, and no no-NaN/no-inf assumptions, which would hide the divergence
# the watchdog must see.
@njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _band_ldlt_solve(band: np.ndarray, inverse_pivots: np.ndarray, rhs: np.ndarray) -> None:
    """Solve a symmetric system of half-bandwidth b = ``KKT_HALF_BANDWIDTH`` in place by LDL^T
    without pivoting.

    Rows b..N-b-1 of ``band`` (N, b + 1) and ``rhs`` (N,) hold the system, ``band[r, s] =
    A[r, r - s]`` (the lower band); the b rows before and after it are zero padding (the band's
    and the right-hand side's), so that every column sees a full band and every loop has a fixed
    trip count. ``band[:, 0]`` is overwritten by D and ``band[:, 1:]`` by L, ``inverse_pivots``
    (N,) receives 1/D, ``rhs`` the solution (the padding rows of ``rhs`` stay zero). The
    saddle-point systems solved here are ordered so that each multiplier follows the particle it
    constrains, which keeps the pivots of the particles positive and those of the multipliers
    negative.

    Column j: ``w_p = L[j, j-p] D[j-p]``, ``D[j] = A[j, j] - sum_p L[j, j-p] w_p``, ``L[j+m, j] =
    (A[j+m, j] - sum_p L[j+m, j-p] w_p) / D[j]``. Every sum runs from the farthest row to the
    nearest, whose term depends on the column just finished: the chain of dependent operations
    from one column to the next is then one term long, not b.
    """
    b = KKT_HALF_BANDWIDTH
    n_rows = band.shape[0]
    for j in range(b, n_rows - b):
        w1 = band[j, 1] * band[j - 1, 0]
        w2 = band[j, 2] * band[j - 2, 0]
        w3 = band[j, 3] * band[j - 3, 0]
        w4 = band[j, 4] * band[j - 4, 0]
        w5 = band[j, 5] * band[j - 5, 0]
        w6 = band[j, 6] * band[j - 6, 0]
        w7 = band[j, 7] * band[j - 7, 0]
        w8 = band[j, 8] * band[j - 8, 0]
        pivot = band[j, 0] - band[j, 8] * w8
        pivot -= band[j, 7] * w7
        pivot -= band[j, 6] * w6
        pivot -= band[j, 5] * w5
        pivot -= band[j, 4] * w4
        pivot -= band[j, 3] * w3
        pivot -= band[j, 2] * w2
        pivot -= band[j, 1] * w1
        band[j, 0] = pivot
        inverse = 1.0 / pivot
        inverse_pivots[j] = inverse
        w = (w1, w2, w3, w4, w5, w6, w7, w8)
        for m in range(1, b + 1):
            i = j + m
            s = band[i, m]
            for p in range(b - m, 0, -1):
                s -= band[i, m + p] * w[p - 1]
            band[i, m] = s * inverse
    for i in range(b, n_rows - b):
        s = rhs[i]
        for p in range(b, 0, -1):
            s -= band[i, p] * rhs[i - p]
        rhs[i] = s
    for i in range(b, n_rows - b):
        rhs[i] *= inverse_pivots[i]
    for i in range(n_rows - b - 1, b - 1, -1):
        s = rhs[i]
        for p in range(b, 0, -1):
            s -= band[i + p, p] * rhs[i + p]
        rhs[i] = s


@njit(cache=True, error_model="numpy", inline="always")
def project_lengths(
    x: np.ndarray,
    inverse_mass: np.ndarray,
    spacing: float,
    tolerance: float,
    max_iterations: int,
    edges: np.ndarray,
    work: np.ndarray,
) -> int:
    """Project chain ``x`` (P, 3) onto ``|x_{i+1} - x_i| = d`` with masses, Eq. (T8).

    Newton iterations of the fast projection: ``(J W J^T) lambda = C(x)``, ``x -= W J^T lambda``
    with ``C_j = |e_j|^2 - d^2``, ``e_j = x_{j+1} - x_j`` and W the inverse masses. J W J^T is
    tridiagonal, solved by the Thomas algorithm: O(P) per iteration, quadratic convergence.
    ``edges`` (P-1, 3) and ``work`` (4, P-1) are scratch. Returns the iterations used, or -1 if
    the relative length error is still above ``tolerance`` after ``max_iterations``.
    """
    segments = x.shape[0] - 1
    d2 = spacing * spacing
    diag = work[0]
    upper = work[1]
    lam = work[2]
    cp = work[3]
    for iteration in range(max_iterations + 1):
        worst = 0.0
        for j in range(segments):
            s = 0.0
            for k in range(3):
                e = x[j + 1, k] - x[j, k]
                edges[j, k] = e
                s += e * e
            lam[j] = s - d2
            worst = max(worst, abs(math.sqrt(s) / spacing - 1.0))
        if not worst <= tolerance:  # also catches NaN
            if iteration == max_iterations or not math.isfinite(worst):
                return -1
        else:
            return iteration
        for j in range(segments):
            ee = 0.0
            for k in range(3):
                ee += edges[j, k] * edges[j, k]
            diag[j] = 4.0 * ee * (inverse_mass[j] + inverse_mass[j + 1])
            if j + 1 < segments:
                dot = 0.0
                for k in range(3):
                    dot += edges[j, k] * edges[j + 1, k]
                upper[j] = -4.0 * inverse_mass[j + 1] * dot
        # Thomas algorithm on (diag, upper) with right-hand side lam (overwritten by lambda).
        cp[0] = upper[0] / diag[0] if segments > 1 else 0.0
        lam[0] = lam[0] / diag[0]
        for j in range(1, segments):
            denominator = diag[j] - upper[j - 1] * cp[j - 1]
            if j + 1 < segments:
                cp[j] = upper[j] / denominator
            lam[j] = (lam[j] - upper[j - 1] * lam[j - 1]) / denominator
        for j in range(segments - 2, -1, -1):
            lam[j] -= cp[j] * lam[j + 1]
        for i in range(segments + 1):
            w = inverse_mass[i]
            if w == 0.0:
                continue
            for k in range(3):
                g = 0.0
                if i >= 1:
                    g += 2.0 * edges[i - 1, k] * lam[i - 1]
                if i < segments:
                    g -= 2.0 * edges[i, k] * lam[i]
                x[i, k] -= w * g
    return -1


@njit(cache=True, error_model="numpy")
def project_on_walls(
    x: np.ndarray,
    inverse_mass: np.ndarray,
    spacing: float,
    tolerance: float,
    max_iterations: int,
    pinned: np.ndarray,
    surface: np.ndarray,
    normals: np.ndarray,
    edges: np.ndarray,
    band: np.ndarray,
    rhs: np.ndarray,
    pushes: np.ndarray,
) -> int:
    """Project chain ``x`` (P, 3) onto its lengths ``|x_{i+1} - x_i| = d`` and, for every
    ``pinned`` particle i, onto the wall's tangent plane where it was put, ``n_i . (x_i - s_i) =
    0`` (``surface`` s_i and unit outward ``normals`` n_i, (P, 3)), together, Eq. (T17): a chain
    pressed on a wall slides along it. Newton iterations of the fast projection on both kinds of
    constraint: ``(J W J^T) lambda = C(x)``, ``x -= W J^T lambda``, W the inverse masses. Ordered
    plane of particle 0, segment 0, plane of particle 1, segment 1, ..., J W J^T has half-bandwidth
    2 (rows of particles not pinned are decoupled identities), solved by LDL^T in O(P).

    ``pushes`` (P,) receives each plane's summed multiplier: a plane holds its particle in, not
    out, where that is positive (its correction ``-w_i lambda_i n_i`` points into the wall).
    ``edges`` (P - 1, 3), ``band`` (2P - 1, 3) and ``rhs`` (2P - 1,) are scratch. Returns the
    iterations used, or -1 if a length or a plane is still off by more than ``tolerance``
    (relative to d) after ``max_iterations`` or the system is singular (a segment along its
    particle's plane normal whose other end cannot move that way: the root, or where no point of
    the plane is at the segment's length from it)."""
    n_particles = x.shape[0]
    segments = n_particles - 1
    rows = 2 * segments + 1
    d2 = spacing * spacing
    pushes[:] = 0.0
    for iteration in range(max_iterations + 1):
        worst = 0.0
        for j in range(segments):
            s = 0.0
            for k in range(3):
                e = x[j + 1, k] - x[j, k]
                edges[j, k] = e
                s += e * e
            rhs[2 * j + 1] = s - d2
            worst = max(worst, abs(math.sqrt(s) / spacing - 1.0))
        for i in range(n_particles):
            if pinned[i]:
                g = 0.0
                for k in range(3):
                    g += normals[i, k] * (x[i, k] - surface[i, k])
                rhs[2 * i] = g
                worst = max(worst, abs(g) / spacing)
            else:
                rhs[2 * i] = 0.0
        if not worst <= tolerance:  # also catches NaN
            if iteration == max_iterations or not math.isfinite(worst):
                return -1
        else:
            return iteration
        # J W J^T in the lower band: band[r, s] = M[r, r - s].
        for r in range(rows):
            band[r, 0] = 0.0
            band[r, 1] = 0.0
            band[r, 2] = 0.0
        for i in range(n_particles):
            w = inverse_mass[i]
            if pinned[i]:
                band[2 * i, 0] = w
                if i >= 1:  # the segment before it: its gradient on x_i is 2 e_{i-1}
                    dot = 0.0
                    for k in range(3):
                        dot += edges[i - 1, k] * normals[i, k]
                    band[2 * i, 1] = 2.0 * w * dot
                if i < segments:  # the segment after it: -2 e_i
                    dot = 0.0
                    for k in range(3):
                        dot += edges[i, k] * normals[i, k]
                    band[2 * i + 1, 1] = -2.0 * w * dot
            else:
                band[2 * i, 0] = 1.0
        for j in range(segments):
            ee = 0.0
            dot = 0.0
            for k in range(3):
                ee += edges[j, k] * edges[j, k]
                if j + 1 < segments:
                    dot += edges[j, k] * edges[j + 1, k]
            band[2 * j + 1, 0] = 4.0 * ee * (inverse_mass[j] + inverse_mass[j + 1])
            if j + 1 < segments:
                band[2 * j + 3, 2] = -4.0 * inverse_mass[j + 1] * dot
        # LDL^T of half-bandwidth 2, in place (L below the diagonal, D on it), then the solve.
        for r in range(rows):
            if r >= 2:
                band[r, 2] /= band[r - 2, 0]
            if r >= 1:
                m1 = band[r, 1]
                if r >= 2:
                    m1 -= band[r, 2] * band[r - 2, 0] * band[r - 1, 1]
                band[r, 1] = m1 / band[r - 1, 0]
            pivot = band[r, 0]
            if r >= 1:
                pivot -= band[r, 1] * band[r, 1] * band[r - 1, 0]
            if r >= 2:
                pivot -= band[r, 2] * band[r, 2] * band[r - 2, 0]
            if not pivot > 1e-14 * band[r, 0]:
                return -1
            band[r, 0] = pivot
        for r in range(1, rows):
            rhs[r] -= band[r, 1] * rhs[r - 1]
            if r >= 2:
                rhs[r] -= band[r, 2] * rhs[r - 2]
        for r in range(rows):
            rhs[r] /= band[r, 0]
        for r in range(rows - 2, -1, -1):
            rhs[r] -= band[r + 1, 1] * rhs[r + 1]
            if r + 2 < rows:
                rhs[r] -= band[r + 2, 2] * rhs[r + 2]
        # x -= W J^T lambda: the segments' 2 e (at the iterate) and the planes' n.
        for i in range(n_particles):
            w = inverse_mass[i]
            if w == 0.0:
                continue
            plane = rhs[2 * i] if pinned[i] else 0.0
            pushes[i] += plane
            for k in range(3):
                g = plane * normals[i, k]
                if i >= 1:
                    g += 2.0 * edges[i - 1, k] * rhs[2 * i - 1]
                if i < segments:
                    g -= 2.0 * edges[i, k] * rhs[2 * i + 1]
                x[i, k] -= w * g
    return -1


MAX_LINEARISATIONS = 8
RELINEARISE_ABOVE = 1.0e-3  # relative length error after a solve that asks for another
PROJECTION_TOLERANCE = 1.0e-10  # relative segment-length error after every step
PROJECTION_MAX_ITERATIONS = 50


@njit(cache=True, inline="always")
def _assemble_slender_particle(
    band: np.ndarray,
    rhs: np.ndarray,
    row: int,
    i: int,
    q: int,
    old: np.ndarray,
    v: np.ndarray,
    u: np.ndarray,
    model: ChainModel,
    medium: Medium,
    dt: float,
    dt2c: float,
    n_particles: int,
    work: np.ndarray,
) -> tuple[float, float]:
    """Particle i's rows of the saddle-point system (Eq. T7) under the slender law (Eq. T14):
    the drag ``K (u - v)`` with ``K = k_n I + (k_t - k_n) t t^T`` implicit in v, its gains from
    the velocity and the tangent t at the start of the step (particle i's share of the chain:
    the chord from i-1 to i+1, length d; an end, tip or free root, its one segment, d/2, as
    its mass is half). ``work`` (2, 3): the tangent is left in row 0. Returns (k_n, k_t)."""
    tangent = work[0]
    relative = work[1]
    lo = i - 1 if i >= 1 else 0
    hi = i + 1 if i + 1 < n_particles else i
    norm = 0.0
    for k in range(3):
        tangent[k] = old[hi, k] - old[lo, k]
        norm += tangent[k] * tangent[k]
        relative[k] = u[k] - v[i, k]
    norm = math.sqrt(norm)
    if norm < 1e-12 * model.spacing:  # folded back on itself: the segment before i (or after)
        lo, hi = (i - 1, i) if i >= 1 else (i, i + 1)
        norm = 0.0
        for k in range(3):
            tangent[k] = old[hi, k] - old[lo, k]
            norm += tangent[k] * tangent[k]
        norm = math.sqrt(norm)
    for k in range(3):
        tangent[k] /= norm
    share = model.spacing if 0 < i < n_particles - 1 else 0.5 * model.spacing  # an end: half
    k_n, k_t = slender_drag_gains(
        tangent,
        relative,
        model.spacing,
        share,
        medium.density,
        model.normal_drag,
        model.tangential_drag,
    )
    m = model.mass[i]
    buoyant = (medium.tentacle_density - medium.density) * model.volume[i]
    bending_diagonal = dt2c * model.stiffness_diag[q]
    for k in range(3):
        # Row k of K = k_n I + (k_t - k_n) t t^T; the band holds the lower triangle.
        kk_diag = k_n + (k_t - k_n) * tangent[k] * tangent[k]
        band[row + k, 0] = m + dt * kk_diag + bending_diagonal
        for kk in range(k):
            band[row + k, k - kk] = dt * (k_t - k_n) * tangent[k] * tangent[kk]
        if q >= 1:
            band[row + k, KKT_BLOCK] = dt2c * model.stiffness_off1[q - 1]
        if q >= 2:
            band[row + k, 2 * KKT_BLOCK] = dt2c * model.stiffness_off2[q - 2]
        k_old = k_n * old[i, k]
        k_u = k_n * u[k]
        along_old = 0.0
        along_u = 0.0
        for kk in range(3):
            along_old += tangent[kk] * old[i, kk]
            along_u += tangent[kk] * u[kk]
        k_old += (k_t - k_n) * tangent[k] * along_old
        k_u += (k_t - k_n) * tangent[k] * along_u
        rhs[row + k] = (
            m * (old[i, k] + dt * v[i, k])
            + dt * k_old
            + dt * dt * (buoyant * medium.gravity[k] + k_u)
        )
    return k_n, k_t


@njit(cache=True, inline="always")
def _add_drag_impulse(
    impulse: np.ndarray,
    gains: np.ndarray,
    flow: np.ndarray,
    x: np.ndarray,
    old: np.ndarray,
    first: int,
    slender: bool,
    dt: float,
) -> None:
    """Add one substep's drag impulse ``dt K (u - v)`` (N s) on each free particle of a chain to
    ``impulse`` (P, 3): K = k I (sphere, ``gains[i, 0]``) or k_n I + (k_t - k_n) t t^T (slender,
    ``gains[i]`` = k_n, k_t, t); ``flow`` (1, 3) or (P, 3), v = (x - old) / dt the velocity of
    the solved step (Eq. T7), before the projection."""
    last = flow.shape[0] - 1
    for i in range(first, x.shape[0]):
        u = flow[min(i, last)]
        w0 = u[0] - (x[i, 0] - old[i, 0]) / dt
        w1 = u[1] - (x[i, 1] - old[i, 1]) / dt
        w2 = u[2] - (x[i, 2] - old[i, 2]) / dt
        k = gains[i, 0]
        if slender:
            t0, t1, t2 = gains[i, 2], gains[i, 3], gains[i, 4]
            along = (gains[i, 1] - k) * (w0 * t0 + w1 * t1 + w2 * t2)
            impulse[i, 0] += dt * (k * w0 + along * t0)
            impulse[i, 1] += dt * (k * w1 + along * t1)
            impulse[i, 2] += dt * (k * w2 + along * t2)
        else:
            impulse[i, 0] += dt * k * w0
            impulse[i, 1] += dt * k * w1
            impulse[i, 2] += dt * k * w2


@njit(cache=True, inline="always")
def _assemble_constraint(
    band: np.ndarray,
    rhs: np.ndarray,
    row: int,
    i: int,
    first: int,
    x: np.ndarray,
    r: np.ndarray,
    d: float,
) -> None:
    """The multiplier row of segment (i-1, i), linearised at the iterate x: n . (x_i - x_{i-1})
    = d with n the segment's direction (Eq. T7); a free root's is a decoupled dummy."""
    lam = row + 3
    if i == 0:
        band[lam, 0] = -1.0
        rhs[lam] = 0.0
        return
    e0 = x[i, 0] - x[i - 1, 0]
    e1 = x[i, 1] - x[i - 1, 1]
    e2 = x[i, 2] - x[i - 1, 2]
    inv = 1.0 / math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    normal = (e0 * inv, e1 * inv, e2 * inv)
    rhs[lam] = d
    for k in range(3):
        band[lam, 3 - k] = normal[k]
        if i - 1 >= first:
            band[lam, 7 - k] = -normal[k]
    if i - 1 < first:  # the segment from the prescribed root
        rhs[lam] += normal[0] * r[0] + normal[1] * r[1] + normal[2] * r[2]


CONTACT_ROUNDS = 32  # pushes out of the bell, each followed by a projection (Eq. T17)
# Where the projection on the walls' tangent planes does not converge: a pushed particle's inverse
# mass in the plain projection after it, of its own, the first that lets it converge (Eq. T17); 1
# is the plain projection, which always does.
HELD_WEIGHTS = (1.0e-3, 1.0e-1, 1.0)
# Of the spacing: how far beyond the surface the rounds push, so that the projection after the
# last one, which may move a particle a little off its plane's point, leaves it outside (Eq. T17).
CONTACT_GAP = 1.0e-3
WALL_RELEASES = 4  # re-projections after letting go of walls that held a particle in (Eq. T17)
# Of the spacing: a wall whose summed correction moved its particle further into it than this held
# it in, and is let go (less is round-off).
WALL_RELEASE_ABOVE = 1.0e-9


@njit(cache=True, error_model="numpy")
def _keep_out(
    x: np.ndarray,
    old: np.ndarray,
    first: int,
    obstacle: Obstacle,
    tau: float,
    inverse_mass: np.ndarray,
    spacing: float,
    iterations: int,
    edges: np.ndarray,
    work: np.ndarray,
    pinned: np.ndarray,
    held: np.ndarray,
    moved: np.ndarray,
    scratch: np.ndarray,
    walls: np.ndarray,
    wall_band: np.ndarray,
    wall_rhs: np.ndarray,
) -> int:
    """Push the chain ``x`` out of the bell's shell and restore its lengths, Eq. (T15-T17): up to
    ``CONTACT_ROUNDS`` times, put the particles inside back on the surface (:func:`push_out`; the
    root's neighbour within the root's reach, Eq. T16b),
    then project the lengths again with every particle pushed so far kept on the wall's tangent
    plane where it was put (:func:`project_on_walls`), so that the chain slides along the wall
    instead of being pulled back into it; a plane that holds its particle in rather than out is let
    go and the projection repeated (up to ``WALL_RELEASES`` times). Where that projection does not
    converge, the pushed particles are held instead (their inverse masses scaled by the first of
    ``HELD_WEIGHTS`` under which the plain projection converges). The rounds alternate between the
    two constraints, as position-based dynamics does (Muller et al., J. Vis. Commun. Image R. 18,
    2007). The lengths are exact on return; a particle may be left inside where the two
    constraints cannot both be met (a root under the wall that sweeps over its chain). Returns the
    most projection iterations of the step, or -1 if a projection failed. ``pinned``, ``moved``
    (P,) bool, ``held`` (P,), ``walls`` (4, P, 3) are scratch: the particles with a plane, those
    pushed in the round, the fallback's inverse masses, and the planes' points and normals, the
    pushed state and the planes' multipliers."""
    surface = walls[0]
    normals = walls[1]
    pushed = walls[2]
    pushes = walls[3, :, 0]
    pinned[:] = False
    for _round in range(CONTACT_ROUNDS):
        moved[:] = False  # this round's pushes
        gap = CONTACT_GAP * spacing
        if push_out(x, old, first, obstacle, tau, moved, scratch, gap, normals, spacing):
            for i in range(first, x.shape[0]):
                if moved[i]:
                    pinned[i] = True
                    for k in range(3):
                        surface[i, k] = x[i, k]  # its plane goes through where it was put
        else:
            break
        pushed[:] = x
        done = -1
        for release in range(WALL_RELEASES + 1):
            done = project_on_walls(
                x, inverse_mass, spacing, PROJECTION_TOLERANCE, PROJECTION_MAX_ITERATIONS,
                pinned, surface, normals, edges, wall_band, wall_rhs, pushes,
            )  # fmt: skip
            if done < 0 or release == WALL_RELEASES:
                break
            let_go = False
            for i in range(first, x.shape[0]):
                if pinned[i] and inverse_mass[i] * pushes[i] > WALL_RELEASE_ABOVE * spacing:
                    pinned[i] = False
                    let_go = True
            if not let_go:
                break
            x[:] = pushed
        if done < 0:
            x[:] = pushed
            for weight in HELD_WEIGHTS:
                for i in range(x.shape[0]):
                    held[i] = weight * inverse_mass[i] if pinned[i] else inverse_mass[i]
                done = project_lengths(
                    x, held, spacing, PROJECTION_TOLERANCE, PROJECTION_MAX_ITERATIONS, edges, work
                )
                if done >= 0:
                    break
                x[:] = pushed  # too stiff a projection to converge: hold the pushed ones less
        if done < 0:
            return -1
        iterations = max(iterations, done)
    return iterations


@njit(cache=True, parallel=True, error_model="numpy")
def advance_frame(
    positions: np.ndarray,
    velocities: np.ndarray,
    root_positions: np.ndarray,
    root_velocities: np.ndarray,
    root_directions: np.ndarray,
    curl_normals: np.ndarray,
    rest_second_differences: np.ndarray,
    flow: np.ndarray,
    model: ChainModel,
    medium: Medium,
    dt: float,
    diagnostics: np.ndarray,
    drag_impulse: np.ndarray,
    obstacle: Obstacle,
) -> None:
    """Advance all chains through the S substeps of one frame, in place.

    ``positions``, ``velocities``: (T, P, 3) state, m and m/s. Per substep s = 0..S-1, at the end
    time of the substep: ``root_positions``, ``root_velocities`` (S, T, 3) the prescribed roots,
    ``root_directions`` (S, T, 3) unit clamp directions t, ``curl_normals`` (S, T, 3) unit normals
    n perpendicular to t (the root frame of the rest shape), ``flow`` (S, T, 1, 3) the water
    velocity (m/s) at the chain, or (S, T, P, 3) at each of its particles.
    ``rest_second_differences`` (T, P, 3) m: each chain's rest shape, the components r_i of its
    rest second differences in the transported frames (Eq. T12); a chain
    whose entries are all zero is straight at rest and skips the rest-shape force entirely. The
    rest-shape force (Eq. T13) is explicit, evaluated at the start of each substep.
    ``diagnostics`` (T, 3) receives per chain: the largest relative
    segment-length error after any substep, the most projection iterations, and the first
    substep whose state was not finite or whose projection failed (-1 if none).
    ``drag_impulse`` (T, P, 3) N s, or (T, 0, 3) to skip it: the water's drag on each particle
    summed over the substeps, ``dt k (u - v)`` with the gain of the step and the velocity of its
    solve (added to what it holds; the reaction that two-way coupling gives the water).
    ``obstacle``: the bell's shell over the frame, which the free particles are kept out of
    after each substep's projection (Eq. T15-T17; :func:`jellysim.tentacle.contact.no_obstacle`
    for none).
    """
    n_chains = positions.shape[0]
    n_particles = positions.shape[1]
    first = 0 if model.free_root else 1  # first free particle
    n_free = n_particles - first
    n_segments = n_particles - 1
    n_unknowns = KKT_BLOCK * n_free
    n_rows = n_unknowns + 2 * KKT_PADDING
    n_substeps = root_positions.shape[0]
    c = model.bending_stiffness
    d = model.spacing
    dt2c = dt * dt * c
    slender = model.drag_law == DRAG_SLENDER
    flow_last = flow.shape[2] - 1  # 0: one water velocity per chain; P - 1: one per particle
    record = drag_impulse.shape[1] > 0
    contact = obstacle.faces.shape[0] > 0
    n_batches = (n_chains + LANES - 1) // LANES
    # LANES chains at a time, each substep's systems solved together, one chain in each lane of
    # a vector register (lanes.py); a chain's arithmetic is that of a chain solved alone.
    for batch in prange(n_batches):
        first_chain = batch * LANES
        lanes = min(LANES, n_chains - first_chain)
        # The systems in rows KKT_PADDING.. of zero-padded storage, lane l holding chain
        # first_chain + l (_band_ldlt_solve, band_ldlt_solve_lanes).
        lane_band = np.empty((n_rows, KKT_HALF_BANDWIDTH + 1, LANES))
        lane_pivots = np.empty((n_rows, LANES))
        lane_rhs = np.zeros((n_rows, LANES))
        olds = np.empty((LANES, n_particles, 3))
        edges = np.empty((n_segments, 3))
        work = np.empty((4, n_segments))
        curled = np.zeros(LANES, dtype=np.bool_)
        for lane in range(lanes):
            for i in range(n_particles):
                for k in range(3):
                    if rest_second_differences[first_chain + lane, i, k] != 0.0:
                        curled[lane] = True
        any_curled = curled.any()
        rest_forces = np.zeros((LANES, n_particles, 3))
        curl_work = np.empty((6, n_particles, 3)) if any_curled else np.empty((6, 0, 3))
        slender_work = np.empty((2, 3))
        # Per lane and particle, the step's drag gains: k (sphere) or k_n, k_t and the tangent
        # (slender).
        lane_gains = np.zeros((LANES, n_particles if record else 0, 5))
        # The contact's work space (Eq. T15-T17), per lane as each chain had its own.
        n_contact = n_particles if contact else 0
        pinned = np.zeros((LANES, n_contact), dtype=np.bool_)
        held = np.empty((LANES, n_contact))
        moved = np.zeros((LANES, n_contact), dtype=np.bool_)
        contact_scratch = np.empty((LANES, 11, 3))
        walls = np.zeros((LANES, 4, n_contact, 3))
        wall_band = np.empty((LANES, max(2 * n_contact - 1, 0), 3))
        wall_rhs = np.empty((LANES, max(2 * n_contact - 1, 0)))
        worst_errors = np.zeros(LANES)
        most_iterations = np.zeros(LANES, dtype=np.int64)
        failed_at = np.full(LANES, -1, dtype=np.int64)
        running = np.zeros(LANES, dtype=np.bool_)  # a chain in the lane, not failed
        running[:lanes] = True
        solving = np.zeros(LANES, dtype=np.bool_)  # lanes whose chain (re)solves its system
        for s in range(n_substeps):
            for lane in range(lanes):
                if not running[lane]:
                    continue
                t = first_chain + lane
                olds[lane] = positions[t]
                if curled[lane]:
                    # The rest shape's force at the start of the step, Eq. (T13).
                    curl_forces(
                        olds[lane],
                        c,
                        root_directions[s, t],
                        curl_normals[s, t],
                        rest_second_differences[t],
                        curl_work,
                        rest_forces[lane],
                    )
            solving[:] = running
            # Sequential linearisation: re-solve with the segment directions of the new iterate
            # while a segment rotates so far in one step that its length is off by > 1e-3.
            for _linearisation in range(MAX_LINEARISATIONS):
                if not solving.any():
                    break
                lane_band[:] = 0.0
                for lane in range(LANES):
                    band = lane_band[KKT_PADDING : KKT_PADDING + n_unknowns, :, lane]
                    rhs = lane_rhs[KKT_PADDING : KKT_PADDING + n_unknowns, lane]
                    if not solving[lane]:
                        # A system of its own for an idle lane, so that it stays finite.
                        band[:, 0] = 1.0
                        rhs[:] = 0.0
                        continue
                    t = first_chain + lane
                    x = positions[t]
                    v = velocities[t]
                    old = olds[lane]
                    gains = lane_gains[lane]
                    rest_force = rest_forces[lane]
                    r = root_positions[s, t]
                    tdir = root_directions[s, t]
                    # Assemble the saddle-point system, Eq. (T7); particle i is block q = i - first.
                    for q in range(n_free):
                        i = q + first
                        row = KKT_BLOCK * q
                        u = flow[s, t, min(i, flow_last)]
                        rel0 = u[0] - v[i, 0]
                        rel1 = u[1] - v[i, 1]
                        rel2 = u[2] - v[i, 2]
                        if slender:
                            k_n, k_t = _assemble_slender_particle(
                                band, rhs, row, i, q, old, v, u, model, medium, dt, dt2c,
                                n_particles, slender_work,
                            )  # fmt: skip
                            if record:
                                gains[i, 0] = k_n
                                gains[i, 1] = k_t
                                for k in range(3):
                                    gains[i, 2 + k] = slender_work[0, k]
                            if curled[lane]:
                                for k in range(3):
                                    rhs[row + k] += dt * dt * rest_force[i, k]
                            _assemble_constraint(band, rhs, row, i, first, x, r, d)
                            continue
                        k_drag = drag_gain(
                            math.sqrt(rel0 * rel0 + rel1 * rel1 + rel2 * rel2),
                            d,
                            medium.density,
                            medium.viscosity,
                        )
                        if record:
                            gains[i, 0] = k_drag
                        m = model.mass[i]
                        buoyant = (medium.tentacle_density - medium.density) * model.volume[i]
                        diagonal = m + dt * k_drag + dt2c * model.stiffness_diag[q]
                        for k in range(3):
                            band[row + k, 0] = diagonal
                            if q >= 1:
                                band[row + k, KKT_BLOCK] = dt2c * model.stiffness_off1[q - 1]
                            if q >= 2:
                                band[row + k, 2 * KKT_BLOCK] = dt2c * model.stiffness_off2[q - 2]
                            rhs[row + k] = (
                                m * (old[i, k] + dt * v[i, k])
                                + dt * k_drag * old[i, k]
                                + dt * dt * (buoyant * medium.gravity[k] + k_drag * u[k])
                            )
                            if curled[lane]:
                                rhs[row + k] += dt * dt * rest_force[i, k]
                        # The multiplier of segment (i-1, i): n . (x_i - x_{i-1}) = d, n its
                        # direction.
                        _assemble_constraint(band, rhs, row, i, first, x, r, d)
                    if first == 1:
                        # The prescribed root enters through the bending coupling, Eq. (T7).
                        for k in range(3):
                            rhs[k] -= dt2c * model.root_coupling[0] * r[k]
                            if n_free > 1:
                                rhs[KKT_BLOCK + k] -= dt2c * model.root_coupling[1] * r[k]
                        if model.clamped:
                            # The clamp's part along t: -(c/2) t t^T on particle 1, Eq. (T3).
                            along = r[0] * tdir[0] + r[1] * tdir[1] + r[2] * tdir[2]
                            for k in range(3):
                                rhs[k] -= 0.5 * dt2c * along * tdir[k]
                                for kk in range(k + 1):
                                    band[k, k - kk] -= 0.5 * dt2c * tdir[k] * tdir[kk]
                _band_ldlt_solve_lanes(lane_band, lane_pivots, lane_rhs)  # type: ignore[call-arg]
                for lane in range(lanes):
                    if not solving[lane]:
                        continue
                    t = first_chain + lane
                    x = positions[t]
                    if first == 1:
                        for k in range(3):
                            x[0, k] = root_positions[s, t, k]
                    for q in range(n_free):
                        for k in range(3):
                            x[q + first, k] = lane_rhs[KKT_PADDING + KKT_BLOCK * q + k, lane]
                    worst = 0.0
                    for j in range(n_segments):
                        e0 = x[j + 1, 0] - x[j, 0]
                        e1 = x[j + 1, 1] - x[j, 1]
                        e2 = x[j + 1, 2] - x[j, 2]
                        worst = max(worst, abs(math.sqrt(e0 * e0 + e1 * e1 + e2 * e2) / d - 1.0))
                    if worst < RELINEARISE_ABOVE:
                        solving[lane] = False
            for lane in range(lanes):
                if not running[lane]:
                    continue
                t = first_chain + lane
                x = positions[t]
                v = velocities[t]
                old = olds[lane]
                if record:
                    # The drag of the solved step, whose momentum balance the projection below
                    # keeps (it moves particles by mass-weighted, momentum-free corrections).
                    _add_drag_impulse(
                        drag_impulse[t], lane_gains[lane], flow[s, t], x, old, first, slender, dt
                    )
                # Exact inextensibility, Eq. (T8).
                iterations = project_lengths(
                    x,
                    model.inverse_mass,
                    d,
                    PROJECTION_TOLERANCE,
                    PROJECTION_MAX_ITERATIONS,
                    edges,
                    work,
                )
                if iterations >= 0 and contact:
                    # Out of the bell's tissue, Eq. (T15-T17): the velocity below carries the
                    # wall's.
                    iterations = _keep_out(
                        x, old, first, obstacle, (s + 1.0) / n_substeps, model.inverse_mass, d,
                        iterations, edges, work, pinned[lane], held[lane], moved[lane],
                        contact_scratch[lane], walls[lane], wall_band[lane], wall_rhs[lane],
                    )  # fmt: skip
                # Velocities from the displacement, Eq. (T9).
                if first == 1:
                    for k in range(3):
                        v[0, k] = root_velocities[s, t, k]
                finite = True
                for i in range(first, n_particles):
                    for k in range(3):
                        v[i, k] = (x[i, k] - old[i, k]) / dt
                        if not math.isfinite(v[i, k]):
                            finite = False
                if iterations < 0 or not finite:
                    failed_at[lane] = s
                    running[lane] = False
                    continue
                most_iterations[lane] = max(most_iterations[lane], iterations)
                for j in range(n_segments):
                    length = math.sqrt(edges[j, 0] ** 2 + edges[j, 1] ** 2 + edges[j, 2] ** 2)
                    worst_errors[lane] = max(worst_errors[lane], abs(length / d - 1.0))
        for lane in range(lanes):
            t = first_chain + lane
            diagnostics[t, 0] = worst_errors[lane]
            diagnostics[t, 1] = most_iterations[lane]
            diagnostics[t, 2] = failed_at[lane]


@njit(cache=True, parallel=True)
def chain_health(positions: np.ndarray, velocities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per chain of ``positions``, ``velocities`` (T, P, 3): the RMS particle speed (m/s) and
    whether every position and velocity is finite; what the run's watchdog reads each frame
    (:meth:`jellysim.simulation.tentacles.ChainGroup.check`), in one pass over the state."""
    n_chains, n_particles = positions.shape[0], positions.shape[1]
    rms = np.empty(n_chains)
    finite = np.empty(n_chains, dtype=np.bool_)
    for t in prange(n_chains):
        total = 0.0
        ok = True
        for i in range(n_particles):
            total += velocities[t, i, 0] ** 2 + velocities[t, i, 1] ** 2 + velocities[t, i, 2] ** 2
            for k in range(3):
                if not math.isfinite(positions[t, i, k]):
                    ok = False
        mean = total / n_particles
        rms[t] = math.sqrt(mean)
        finite[t] = ok and math.isfinite(mean)
    return rms, finite
