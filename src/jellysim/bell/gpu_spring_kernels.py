"""The soft bell's CUDA kernels (Numba), for :class:`jellysim.bell.gpu_springs.GPUSprings`:
module-level functions, so that Numba caches their machine code (``cache=True``, as
:mod:`jellysim.fluid.gpu_kernels`). Imported on the first GPU bell; the equations are
:mod:`jellysim.bell.gpu_springs`'s docstring's.
"""

import math

from numba import cuda


@cuda.jit(cache=True)
def spring_terms(
    position, base, pairs, rest_length, share, stiffness, ratio_a, stiffening_a,
    tension, normal, along, across,
):  # fmt: skip
    """Per spring e = (a, b) at the activation's ``ratio_a`` = muscle_ratio a and
    ``stiffening_a`` = (muscle_stiffening - 1) a: L_e = L0 (1 - ratio_a share_e),
    k_e = k (1 + stiffening_a share_e) (Eq. B9; share 0 for a passive spring);
    ``tension`` f_e = k_e (|d| - L_e) d / |d| with d = r_b - r_a (Eq. B8), ``normal`` n,
    ``along`` k_e and ``across`` k_e max(1 - L_e / |d|, 0)."""
    e = cuda.grid(1)
    if e >= pairs.shape[0]:
        return
    a = base + pairs[e, 0]
    b = base + pairs[e, 1]
    length_rest = rest_length[e] * (1.0 - ratio_a * share[e])
    k = stiffness * (1.0 + stiffening_a * share[e])
    d0 = position[b, 0] - position[a, 0]
    d1 = position[b, 1] - position[a, 1]
    d2 = position[b, 2] - position[a, 2]
    length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    scale = 0.0
    n0 = d0
    n1 = d1
    n2 = d2
    stretch = 0.0
    if length > 0.0:
        scale = k * (length - length_rest) / length
        n0 = d0 / length
        n1 = d1 / length
        n2 = d2 / length
        stretch = max(1.0 - length_rest / length, 0.0)
    tension[e, 0] = scale * d0
    tension[e, 1] = scale * d1
    tension[e, 2] = scale * d2
    normal[e, 0] = n0
    normal[e, 1] = n1
    normal[e, 2] = n2
    along[e] = k if length > 0.0 else 0.0
    across[e] = k * stretch


@cuda.jit(cache=True)
def explicit(tension, start, edges, signs, volume, base, reaction, with_reaction, out):
    """``out[base + i]`` = F_i / l0^3 (+ the reaction there), F_i the sum of ``sign * f_e``
    over particle i's springs in adjacency order (:func:`gather_forces`)."""
    i = cuda.grid(1)
    if i >= start.shape[0] - 1:
        return
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    for m in range(start[i], start[i + 1]):
        e = edges[m]
        s = signs[m]
        f0 += s * tension[e, 0]
        f1 += s * tension[e, 1]
        f2 += s * tension[e, 2]
    row = base + i
    if with_reaction:
        out[row, 0] = reaction[row, 0] + f0 / volume
        out[row, 1] = reaction[row, 1] + f1 / volume
        out[row, 2] = reaction[row, 2] + f2 / volume
    else:
        out[row, 0] = f0 / volume
        out[row, 1] = f1 / volume
        out[row, 2] = f2 / volume


@cuda.jit(cache=True)
def implicit(
    velocity, base, pairs, start, edges, signs, tension, normal, along, across, mass, dt,
    index, count, coefficient, diagonal, inverse_diagonal, rhs, guess,
):  # fmt: skip
    """Particle i's three rows 3i + k of ``(m I - dt^2 K) dv = dt (F + dt K v)``: K's
    block for spring e to the other end o is K_io = K_e and K_ii = -sum K_e, so the row
    holds ``-dt^2 K_e`` at o's three columns and ``m I + dt^2 sum K_e`` on i's; stored as
    the pressure's rows, ``A x = diagonal x_i - sum coefficient x_index``. ``rhs`` the
    right side, ``guess`` dt F / m."""
    i = cuda.grid(1)
    if i >= start.shape[0] - 1:
        return
    h2 = dt * dt
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    kv0 = 0.0
    kv1 = 0.0
    kv2 = 0.0
    s00 = 0.0
    s01 = 0.0
    s02 = 0.0
    s11 = 0.0
    s12 = 0.0
    s22 = 0.0
    slot = 2
    for m in range(start[i], start[i + 1]):
        e = edges[m]
        s = signs[m]
        f0 += s * tension[e, 0]
        f1 += s * tension[e, 1]
        f2 += s * tension[e, 2]
        a = base + pairs[e, 0]
        b = base + pairs[e, 1]
        other = pairs[e, 1] if s > 0.0 else pairs[e, 0]
        n0 = normal[e, 0]
        n1 = normal[e, 1]
        n2 = normal[e, 2]
        p = along[e]
        q = across[e]
        # K_e (v_b - v_a), the force on a; on b it is minus that
        v0 = velocity[b, 0] - velocity[a, 0]
        v1 = velocity[b, 1] - velocity[a, 1]
        v2 = velocity[b, 2] - velocity[a, 2]
        dot = n0 * v0 + n1 * v1 + n2 * v2
        kv0 += s * (p * n0 * dot + q * (v0 - n0 * dot))
        kv1 += s * (p * n1 * dot + q * (v1 - n1 * dot))
        kv2 += s * (p * n2 * dot + q * (v2 - n2 * dot))
        # K_e = (p - q) n n^T + q I
        c = p - q
        b00 = c * n0 * n0 + q
        b01 = c * n0 * n1
        b02 = c * n0 * n2
        b11 = c * n1 * n1 + q
        b12 = c * n1 * n2
        b22 = c * n2 * n2 + q
        s00 += b00
        s01 += b01
        s02 += b02
        s11 += b11
        s12 += b12
        s22 += b22
        for k in range(3):
            row = 3 * i + k
            index[slot, row] = 3 * other
            index[slot + 1, row] = 3 * other + 1
            index[slot + 2, row] = 3 * other + 2
        coefficient[slot, 3 * i] = h2 * b00
        coefficient[slot + 1, 3 * i] = h2 * b01
        coefficient[slot + 2, 3 * i] = h2 * b02
        coefficient[slot, 3 * i + 1] = h2 * b01
        coefficient[slot + 1, 3 * i + 1] = h2 * b11
        coefficient[slot + 2, 3 * i + 1] = h2 * b12
        coefficient[slot, 3 * i + 2] = h2 * b02
        coefficient[slot + 1, 3 * i + 2] = h2 * b12
        coefficient[slot + 2, 3 * i + 2] = h2 * b22
        slot += 3
    # i's own block: the two other components of each row in slots 0 and 1
    r0 = 3 * i
    r1 = r0 + 1
    r2 = r0 + 2
    index[0, r0] = r1
    index[1, r0] = r2
    coefficient[0, r0] = -h2 * s01
    coefficient[1, r0] = -h2 * s02
    index[0, r1] = r0
    index[1, r1] = r2
    coefficient[0, r1] = -h2 * s01
    coefficient[1, r1] = -h2 * s12
    index[0, r2] = r0
    index[1, r2] = r1
    coefficient[0, r2] = -h2 * s02
    coefficient[1, r2] = -h2 * s12
    diagonal[r0] = mass + h2 * s00
    diagonal[r1] = mass + h2 * s11
    diagonal[r2] = mass + h2 * s22
    for r in range(r0, r0 + 3):
        count[r] = slot
        inverse_diagonal[r] = 1.0 / diagonal[r]
    rhs[r0] = dt * (f0 + dt * kv0)
    rhs[r1] = dt * (f1 + dt * kv1)
    rhs[r2] = dt * (f2 + dt * kv2)
    guess[r0] = dt * f0 / mass
    guess[r1] = dt * f1 / mass
    guess[r2] = dt * f2 / mass


@cuda.jit(cache=True)
def from_velocity_change(change, mass, dt, volume, base, reaction, with_reaction, out):
    """``out[base + i]`` = (m dv_i / dt) / l0^3 (+ the reaction there)."""
    i = cuda.grid(1)
    if i >= change.shape[0] // 3:
        return
    row = base + i
    for k in range(3):
        density = mass * change[3 * i + k] / dt / volume
        if with_reaction:
            density = reaction[row, k] + density
        out[row, k] = density


# every kernel by name, as GPUSprings looks them up
KERNELS = {
    "spring_terms": spring_terms,
    "explicit": explicit,
    "implicit": implicit,
    "from_velocity_change": from_velocity_change,
}
