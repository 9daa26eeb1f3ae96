"""The MPS fluid on an NVIDIA GPU (``fluid.device = "cuda"``): the step of
:class:`jellysim.fluid.mps.MPSSolver` in CUDA kernels (Numba), the state kept on the GPU.

The same equations as the CPU path (docs/theory/fluid.md, Eq. F1-F13), every option of
:class:`~jellysim.fluid.mps.MPSParameters` but the pressure solver: the CPU's IC(0) and its
coarse-space deflation (a sparse direct coarse solve each iteration) do not suit a GPU. The
pressure is solved by CG preconditioned by Jacobi, and with ``solver = "deflated"`` (every
preset's) by Jacobi plus a coarse correction on aggregates, ``M^-1 r = D^-1 r + Z E^-1 Z^T r``
(Eq. F12b), E^-1 dense on the GPU and made on the host once a frame (docs/decisions.md). The
neighbour lists are of fixed width: ``width`` slots a particle (grown, and the search repeated,
when a particle has more neighbours), in the order of the cells around it and of particle
index within a cell, so that each particle sums its neighbours in one fixed order.

Reproducible: no floating-point atomic sums. A dot product sums within each block of
:data:`BLOCK` threads by a fixed tree; after a grid barrier every block sums the blocks' sums
in one fixed order (each thread a strided share, then the tree). The atomics left are order-free:
integer counts, and the maxima of :meth:`GPUSolver.stable_dt`. Two runs on one GPU give the same
bits; another card (the solve's grid is as many blocks as it holds at once) or the simulator
(one block) gives other round-off, and the CPU path sums in another order with another solver:
the paths agree to the solver's tolerance, not bit for bit.

Without a GPU, Numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``, set before Numba is
imported) runs the same kernels in Python threads: the unit tests run them so on tiny scenes
(``tests/unit/test_fluid_gpu.py``); ``make test-gpu`` runs the suite on a real GPU.
"""

from __future__ import annotations

import logging
import math
import os
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import scipy.linalg.lapack

from jellysim.fluid.geometry import DUMMY, FLUID, WALL
from jellysim.fluid.kernels import CORRECTION_MIN_DETERMINANT
from jellysim.fluid.mps import (
    MPSParameters,
    PhaseTimer,
    StepStats,
    lattice_reference,
    solver_setup,
    step_limits,
)
from jellysim.fluid.solvers import FluidDiverged

log = logging.getLogger(__name__)

# numba-cuda 0.30 registers an overload of np.row_stack when it compiles its first kernel, and
# NumPy 2.5 removed that alias of np.vstack: without it no kernel compiles (docs/decisions.md).
if not hasattr(np, "row_stack"):
    np.row_stack = np.vstack  # type: ignore[attr-defined]

try:  # Numba's CUDA support; kernels use it as a module global (the simulator swaps those)
    from numba import cuda, float64, int32
except Exception as _error:  # noqa: BLE001 - any failure means: no CUDA here
    cuda = None  # type: ignore[assignment]
    _CUDA_ERROR = str(_error)


def quiet_small_grid_warnings() -> None:
    """The coarse space's kernels, and every kernel in a small tank, launch a few blocks on
    purpose; numba-cuda warns of each such launch ("Grid size 1 will likely result in GPU
    under-utilization", after a terminal colour code where colorama is installed), which tells
    a user of jellysim nothing they can act on. Called when a GPU solver is made."""
    warnings.filterwarnings(
        "ignore", message=r".*Grid size \d+ will likely result in GPU under-utilization"
    )


def simulated() -> bool:
    """Whether Numba runs CUDA kernels in its simulator (``NUMBA_ENABLE_CUDASIM=1``)."""
    return os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0")


# Threads of a block. The dot products' partial sums are per block, so the round-off of a
# solve depends on it (and on the number of blocks).
BLOCK = 128
# The neighbour lists' width: this many times the neighbours of a particle on the perfect
# lattice within the search radius, plus a few (compressed water and collisions give more;
# the search grows the width and runs again when some particle has more).
WIDTH_FACTOR = 1.4

# The two-level preconditioner (``fluid.solver = "deflated"`` on the GPU): aggregates are blocks
# of k x k (x k) search cells, k the nearest to ``coarse_cell`` l0 and grown until there are at
# most one per COARSE_PARTICLES particles and COARSE_LARGEST in all (E^-1 is dense on the GPU,
# factored on the host: more aggregates save iterations and cost a larger factorisation). E^-1
# is made anew at each frame's first solve (so that a resumed run solves as the run), when a
# solve takes more than COARSE_STALE times the iterations of the first solve with it (plus two),
# or after COARSE_REFRESH steps: an E^-1 some steps old costs a few iterations (measured on the
# CPU: 39 -> 44 after 50 steps of tank-3d), its making a download, a factorisation on the host
# and an upload (docs/decisions.md). Iteration counts are deterministic, so the refreshes fall
# on the same steps in two runs.
COARSE_LARGEST = 2500
COARSE_PARTICLES = 200
COARSE_REFRESH = 200
COARSE_STALE = 1.25
# The dense product with E^-1 in this many chunks of columns, so that m x CHUNKS threads share it.
COARSE_CHUNKS = 32

_KERNELS: dict[str, Any] | None = None


def unavailable() -> str | None:
    """Why the GPU path cannot run here (a sentence saying what to install), or None."""
    if cuda is None:
        return (
            f"fluid.device = 'cuda' needs Numba's CUDA support ({_CUDA_ERROR}); install it "
            "with `pip install jellysim[cuda]`"
        )
    if simulated():
        return None
    try:
        if cuda.is_available() and len(cuda.gpus) > 0:
            return None
    except Exception:  # noqa: BLE001,S110 - a broken driver reads as no GPU
        pass
    return (
        "fluid.device = 'cuda' needs an NVIDIA GPU with its driver and the CUDA runtime, and "
        "none was found; install `pip install jellysim[cuda]` (numba-cuda and the CUDA "
        "libraries) on a machine with an NVIDIA GPU, or set fluid.device = 'cpu'"
    )


def free_memory() -> tuple[int, str] | None:
    """The GPU's free memory (bytes) and its name, for the run estimate's check; None where no
    GPU can run (:func:`unavailable`) or in the simulator, which has no memory of its own."""
    if simulated() or unavailable() is not None:
        return None
    try:
        free, _total = cuda.current_context().get_memory_info()
        name = cuda.get_current_device().name
        return int(free), name.decode() if isinstance(name, bytes) else str(name)
    except Exception:  # noqa: BLE001 - a driver that cannot say: the run finds out itself
        return None


def _kernels() -> dict[str, Any]:
    """The CUDA kernels, compiled on first use (Numba's CUDA module is imported only here)."""
    global _KERNELS
    if _KERNELS is None:
        _KERNELS = _build_kernels()
    return _KERNELS


def _build_kernels() -> dict[str, Any]:  # noqa: C901, PLR0915 - one closure per kernel
    fluid_kind, wall_kind, dummy_kind = FLUID, WALL, DUMMY
    block = BLOCK
    min_det = CORRECTION_MIN_DETERMINANT

    @cuda.jit(device=True)
    def weight(r, re):
        if r < re:
            return re / r - 1.0
        return 0.0

    @cuda.jit(device=True)
    def block_sum(shared, value):
        """The sum of ``value`` over the block, in a fixed tree order (every thread gets it)."""
        t = cuda.threadIdx.x
        shared[t] = value
        cuda.syncthreads()
        step = block // 2
        while step > 0:
            if t < step:
                shared[t] += shared[t + step]
            cuda.syncthreads()
            step //= 2
        total = shared[0]
        cuda.syncthreads()
        return total

    # ------------------------------------------------------------------------ neighbour search

    @cuda.jit(device=True)
    def cell_coordinate(x, lower, inverse, size):
        c = int(math.floor((x - lower) * inverse))
        if c < 0:
            return 0
        if c >= size:
            return size - 1
        return c

    @cuda.jit
    def cell_of(position, alive, lower, inverse, shape, cell, count):
        i = cuda.grid(1)
        if i >= position.shape[0]:
            return
        if not alive[i]:
            cell[i] = -1
            return
        dim = position.shape[1]
        cx = cell_coordinate(position[i, 0], lower[0], inverse, shape[0])
        cy = cell_coordinate(position[i, 1], lower[1], inverse, shape[1])
        cz = 0
        if dim == 3:
            cz = cell_coordinate(position[i, 2], lower[2], inverse, shape[2])
        c = cx + shape[0] * (cy + shape[1] * cz)
        cell[i] = c
        cuda.atomic.add(count, c, 1)

    @cuda.jit(device=True)
    def block_scan(shared, value):
        """The inclusive prefix sum of ``value`` over the block's threads (integers)."""
        t = cuda.threadIdx.x
        shared[t] = value
        cuda.syncthreads()
        offset = 1
        while offset < block:
            add = 0
            if t >= offset:
                add = shared[t - offset]
            cuda.syncthreads()
            shared[t] += add
            cuda.syncthreads()
            offset *= 2
        total = shared[t]
        cuda.syncthreads()
        return total

    @cuda.jit
    def tile_sums(count, sums):
        """The cell counts of each tile of ``block`` cells."""
        shared = cuda.shared.array(block, dtype=int32)
        c = cuda.grid(1)
        value = count[c] if c < count.shape[0] else 0
        total = block_scan(shared, value)
        if cuda.threadIdx.x == block - 1:
            sums[cuda.blockIdx.x] = total

    @cuda.jit
    def tile_offsets(sums, offsets):
        """``offsets[b]``: the cells before tile b (one block, a chunk of tiles at a time)."""
        shared = cuda.shared.array(block, dtype=int32)
        t = cuda.threadIdx.x
        carry = 0
        for first in range(0, sums.shape[0], block):
            b = first + t
            own = sums[b] if b < sums.shape[0] else 0
            inclusive = block_scan(shared, own)
            if b < sums.shape[0]:
                offsets[b] = carry + inclusive - own
            if t == block - 1:  # the chunk's total, to every thread
                shared[0] = inclusive
            cuda.syncthreads()
            carry += shared[0]
            cuda.syncthreads()

    @cuda.jit
    def scan_tiles(count, offsets, start):
        """``start[0] = 0``, ``start[c + 1] = start[c] + count[c]``."""
        shared = cuda.shared.array(block, dtype=int32)
        c = cuda.grid(1)
        value = count[c] if c < count.shape[0] else 0
        inclusive = block_scan(shared, value)
        if c < count.shape[0]:
            start[c + 1] = offsets[cuda.blockIdx.x] + inclusive
        if c == 0:
            start[0] = 0

    @cuda.jit
    def scatter(cell, start, cursor, member):
        i = cuda.grid(1)
        if i >= cell.shape[0]:
            return
        c = cell[i]
        if c >= 0:
            member[start[c] + cuda.atomic.add(cursor, c, 1)] = i

    @cuda.jit
    def sort_cells(start, member):
        """Each cell's members in particle order (the scatter's order is the atomics')."""
        c = cuda.grid(1)
        if c >= start.shape[0] - 1:
            return
        for a in range(start[c] + 1, start[c + 1]):
            value = member[a]
            b = a - 1
            while b >= start[c] and member[b] > value:
                member[b + 1] = member[b]
                b -= 1
            member[b + 1] = value

    @cuda.jit
    def search(
        position, rows, every, kind, cell, start, member, shape, radius, index, distance, count,
        most,
    ):  # fmt: skip
        """Row i (``rows[i]``, or every live fluid and wall particle where ``every[-1]`` is 1):
        the live particles within ``radius`` of particle i but itself, over the 3^D cells
        around its own in order, members in particle order."""
        i = cuda.grid(1)
        if i >= position.shape[0]:
            return
        found = 0
        width = index.shape[0]
        c = cell[i]
        row = rows[i] or (every[every.shape[0] - 1] == 1 and kind[i] != dummy_kind)
        if row and c >= 0:
            dim = position.shape[1]
            cx = c % shape[0]
            cy = (c // shape[0]) % shape[1]
            cz = c // (shape[0] * shape[1])
            r2max = radius * radius
            xi = position[i, 0]
            yi = position[i, 1]
            zi = 0.0
            if dim == 3:
                zi = position[i, 2]
            for z in range(max(cz - 1, 0), min(cz + 2, shape[2])):
                for y in range(max(cy - 1, 0), min(cy + 2, shape[1])):
                    for x in range(max(cx - 1, 0), min(cx + 2, shape[0])):
                        k = x + shape[0] * (y + shape[1] * z)
                        for m in range(start[k], start[k + 1]):
                            j = member[m]
                            if j == i:
                                continue
                            dx = position[j, 0] - xi
                            dy = position[j, 1] - yi
                            r2 = dx * dx + dy * dy
                            if dim == 3:
                                dz = position[j, 2] - zi
                                r2 += dz * dz
                            if r2 < r2max:
                                if found < width:
                                    index[found, i] = j
                                    distance[found, i] = math.sqrt(r2)
                                found += 1
        count[i] = min(found, width)
        if found > width:
            cuda.atomic.max(most, 0, found)

    # ------------------------------------------------------------------------ particle models

    @cuda.jit
    def number_density(index, distance, count, re, out, within):
        """Eq. (F2), and the neighbours within r_e (neighbour-count surface)."""
        i = cuda.grid(1)
        if i >= count.shape[0]:
            return
        total = 0.0
        found = 0
        for m in range(count[i]):
            r = distance[m, i]
            if r < re:
                total += weight(r, re)
                found += 1
        out[i] = total
        within[i] = found

    @cuda.jit
    def explicit_stage(
        position, velocity, kind, alive, index, distance, count, re, coefficient, gravity,
        external, has_external, density, dt, out_position, out_velocity,
    ):  # fmt: skip
        """Eq. (F5): u* and r* of live fluid particles; other particles copied."""
        i = cuda.grid(1)
        if i >= position.shape[0]:
            return
        dim = position.shape[1]
        for k in range(dim):
            out_velocity[i, k] = velocity[i, k]
            out_position[i, k] = position[i, k]
        if not (alive[i] and kind[i] == fluid_kind):
            return
        lap = cuda.local.array(3, dtype=float64)
        for k in range(3):
            lap[k] = 0.0
        for m in range(count[i]):
            r = distance[m, i]
            if r < re:
                j = index[m, i]
                w = weight(r, re)
                for k in range(dim):
                    lap[k] += (velocity[j, k] - velocity[i, k]) * w
        for k in range(dim):
            a = gravity[k]
            if has_external:
                a += external[i, k] / density
            u = velocity[i, k] + dt * (coefficient * lap[k] + a)
            out_velocity[i, k] = u
            out_position[i, k] = position[i, k] + dt * u

    @cuda.jit
    def collision(
        position, velocity, kind, alive, index, count, reach, half, dt, out_position, out_velocity,
    ):  # fmt: skip
        """Eq. (F6), the Jacobi form of :func:`jellysim.fluid.kernels.collision`."""
        i = cuda.grid(1)
        if i >= position.shape[0]:
            return
        dim = position.shape[1]
        for k in range(dim):
            out_velocity[i, k] = velocity[i, k]
            out_position[i, k] = position[i, k]
        if not (alive[i] and kind[i] == fluid_kind):
            return
        for m in range(count[i]):
            j = index[m, i]
            if not alive[j]:
                continue
            r2 = 0.0
            for k in range(dim):
                d = position[j, k] - position[i, k]
                r2 += d * d
            if r2 >= reach * reach or r2 == 0.0:
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

    @cuda.jit
    def classify(
        alive, kind, density_star, density_start, within, threshold, by_count, count_threshold,
        either, unknown, surface_count,
    ):  # fmt: skip
        """The unknowns of the PPE: live fluid and wall particles not on the free surface, Eq.
        (F7) or (F7b) (``unknown`` 1, else 0)."""
        i = cuda.grid(1)
        if i >= alive.shape[0]:
            return
        solid = alive[i] and kind[i] != dummy_kind
        surface = density_star[i] < threshold
        if by_count and within[i] < count_threshold:
            surface = True
        if either and density_start[i] < threshold:
            surface = True
        unknown[i] = 1 if (solid and not surface) else 0
        if solid and surface:
            cuda.atomic.add(surface_count, 0, 1)

    @cuda.jit
    def assemble(
        position, velocity, kind, alive, index, distance, count, unknown, re_lap, a_coefficient,
        shift, re_grad, div_coefficient, mixed, source_scale, mixed_scale, n0, density_star,
        density_start, pressure, coefficient, diagonal, inverse_diagonal, b, x,
    ):  # fmt: skip
        """Eq. (F8)-(F9): the PPE row of particle i (``coefficient[m, i]`` = a_ij for unknown
        neighbours, 0 else; ``diagonal``), its source ``b`` and the warm start ``x``; zeros for
        the particles that are no unknowns."""
        i = cuda.grid(1)
        if i >= unknown.shape[0]:
            return
        width = coefficient.shape[0]
        if unknown[i] == 0:
            for m in range(width):
                coefficient[m, i] = 0.0
            diagonal[i] = 0.0
            inverse_diagonal[i] = 0.0
            b[i] = 0.0
            x[i] = 0.0
            return
        dim = position.shape[1]
        total = 0.0
        divergence = 0.0
        for m in range(count[i]):
            r = distance[m, i]
            j = index[m, i]
            coefficient[m, i] = 0.0
            if kind[j] == dummy_kind or not alive[j]:
                continue
            if r < re_lap:
                a = a_coefficient * weight(r, re_lap)
                total += a
                if unknown[j] == 1:
                    coefficient[m, i] = a
            if mixed and r < re_grad:
                dot = 0.0
                for k in range(dim):
                    dot += (velocity[j, k] - velocity[i, k]) * (position[j, k] - position[i, k])
                divergence += dot / (r * r) * weight(r, re_grad)
        for m in range(count[i], width):
            coefficient[m, i] = 0.0
        diagonal[i] = total + shift
        inverse_diagonal[i] = 1.0 / (total + shift)
        if mixed:
            deviation = (density_start[i] - n0) / n0
            b[i] = -source_scale * (div_coefficient * divergence) + mixed_scale * deviation
        else:
            b[i] = source_scale * ((density_star[i] - n0) / n0)
        x[i] = pressure[i]

    # ------------------------------------------------------------ the coarse space (two-level)

    @cuda.jit(device=True)
    def coarse_block(c, shape, k, coarse_shape):
        """The aggregate of search cell ``c``: the block of k x k (x k) cells it lies in."""
        cx = c % shape[0]
        rest = c // shape[0]
        cy = rest % shape[1]
        cz = rest // shape[1]
        return cx // k + coarse_shape[0] * (cy // k + coarse_shape[1] * (cz // k))

    @cuda.jit(device=True)
    def aggregate_sum(aggregate, cell_sums, shape, k, coarse_shape):
        """The sum of ``cell_sums`` over an aggregate's search cells, in cell order."""
        bx = aggregate % coarse_shape[0]
        rest = aggregate // coarse_shape[0]
        by = rest % coarse_shape[1]
        bz = rest // coarse_shape[1]
        total = 0.0
        for fz in range(bz * k, min(bz * k + k, shape[2])):
            for fy in range(by * k, min(by * k + k, shape[1])):
                for fx in range(bx * k, min(bx * k + k, shape[0])):
                    total += cell_sums[fx + shape[0] * (fy + shape[1] * fz)]
        return total

    @cuda.jit
    def coarse_flags(cell, diagonal, shape, k, coarse_shape, flags):
        """``flags[a]`` 1 for the aggregates that hold an unknown row (the same value written
        by every such row: the result does not depend on the order)."""
        i = cuda.grid(1)
        if i < cell.shape[0] and cell[i] >= 0 and diagonal[i] != 0.0:
            flags[coarse_block(cell[i], shape, k, coarse_shape)] = 1

    @cuda.jit
    def coarse_matrix(
        cell, start, member, index, count, coefficient, diagonal, shape, k, coarse_shape,
        to_coarse, blocks, e,
    ):  # fmt: skip
        """Row a of the coarse operator E = Z^T A Z (dense, m x m, zero on entry): the sum of
        A's entries between the rows of aggregate ``blocks[a]`` and those of each other
        aggregate (A_ii = ``diagonal``, A_ij = -``coefficient``), in the aggregates' fixed
        order."""
        a = cuda.grid(1)
        if a >= blocks.shape[0]:
            return
        aggregate = blocks[a]
        bx = aggregate % coarse_shape[0]
        rest = aggregate // coarse_shape[0]
        by = rest % coarse_shape[1]
        bz = rest // coarse_shape[1]
        for fz in range(bz * k, min(bz * k + k, shape[2])):
            for fy in range(by * k, min(by * k + k, shape[1])):
                for fx in range(bx * k, min(bx * k + k, shape[0])):
                    c = fx + shape[0] * (fy + shape[1] * fz)
                    for s in range(start[c], start[c + 1]):
                        i = member[s]
                        if diagonal[i] == 0.0:
                            continue
                        e[a, a] += diagonal[i]
                        for t in range(count[i]):
                            value = coefficient[t, i]
                            j = index[t, i]
                            if value != 0.0 and cell[j] >= 0:
                                col = to_coarse[coarse_block(cell[j], shape, k, coarse_shape)]
                                if col >= 0:
                                    e[a, col] -= value

    @cuda.jit(device=True)
    def two_level(
        r, z, diagonal, inverse_diagonal, cell, start, member, shape, k, coarse_shape,
        to_coarse, blocks, inverse, cell_sums, coarse_r, partial, coarse_z,
    ):  # fmt: skip
        """``z = D^-1 r + Z E^-1 Z^T r`` over the grid (``r`` complete on entry; each thread
        writes z on its own rows): r summed over each search cell's members (in particle order,
        the search's sorted lists) and then over each aggregate's cells, the dense product with
        E^-1 in ``partial.shape[0]`` chunks of columns (their sums in chunk order), and each
        unknown row's aggregate's value added to its Jacobi term. Fixed orders throughout."""
        grid = cuda.cg.this_grid()
        first = cuda.grid(1)
        stride = cuda.gridsize(1)
        for c in range(first, start.shape[0] - 1, stride):
            total = 0.0
            for s in range(start[c], start[c + 1]):
                total += r[member[s]]
            cell_sums[c] = total
        grid.sync()
        m = blocks.shape[0]
        for a in range(first, m, stride):
            coarse_r[a] = aggregate_sum(blocks[a], cell_sums, shape, k, coarse_shape)
        grid.sync()
        chunks = partial.shape[0]
        length = (m + chunks - 1) // chunks
        for w in range(first, m * chunks, stride):
            a = w % m  # consecutive threads: consecutive a, one row of the symmetric E^-1
            chunk = w // m
            total = 0.0
            for col in range(chunk * length, min(chunk * length + length, m)):
                total += inverse[col, a] * coarse_r[col]
            partial[chunk, a] = total
        grid.sync()
        for a in range(first, m, stride):
            total = 0.0
            for chunk in range(chunks):
                total += partial[chunk, a]
            coarse_z[a] = total
        grid.sync()
        for i in range(first, r.shape[0], stride):
            zi = inverse_diagonal[i] * r[i]
            if diagonal[i] != 0.0 and cell[i] >= 0:
                col = to_coarse[coarse_block(cell[i], shape, k, coarse_shape)]
                if col >= 0:
                    zi += coarse_z[col]
            z[i] = zi

    # ------------------------------------------------------------------- conjugate gradients

    @cuda.jit(device=True)
    def product(i, index, count, coefficient, diagonal, v):
        total = diagonal[i] * v[i]
        for m in range(count[i]):
            total -= coefficient[m, i] * v[index[m, i]]
        return total

    @cuda.jit(device=True)
    def post(partial, slot, a, c, e, shared):
        """The block's sums of ``a``, ``c``, ``e`` into ``partial[slot, block]``."""
        total_a = block_sum(shared, a)
        total_c = block_sum(shared, c)
        total_e = block_sum(shared, e)
        if cuda.threadIdx.x == 0:
            partial[slot, cuda.blockIdx.x, 0] = total_a
            partial[slot, cuda.blockIdx.x, 1] = total_c
            partial[slot, cuda.blockIdx.x, 2] = total_e

    @cuda.jit(device=True)
    def gathered(partial, slot, column, shared):
        """The sum over the blocks of ``partial[slot, :, column]``, in block order within each
        thread's share and then by :func:`block_sum` (every thread of every block gets the
        same number)."""
        value = 0.0
        k = cuda.threadIdx.x
        while k < cuda.gridDim.x:
            value += partial[slot, k, column]
            k += block
        return block_sum(shared, value)

    @cuda.jit
    def conjugate_gradient(
        index, count, coefficient, diagonal, inverse_diagonal, b, x, r, z, d, q, partial,
        tolerance2, max_iterations, out, cell, start, member, shape, k, coarse_shape,
        to_coarse, blocks, inverse, cell_sums, coarse_r, coarse_partial, coarse_z,
    ):  # fmt: skip
        """Preconditioned CG for ``A x = b`` from the guess in ``x``, all iterations in one
        cooperative launch: each thread takes every gridsize-th row, and the grid meets at
        three barriers an iteration (the dot products' block sums are posted to one of two
        slots by turns, so that a slot is rewritten only after every block has read it).
        The preconditioner is Jacobi, or with aggregates (``blocks`` not empty) Jacobi plus
        the coarse correction of :func:`two_level`, five barriers more. Stops when ``r.r <=
        tolerance2 b.b`` or after ``max_iterations``; ``out`` = (iterations, r.r, b.b). Every
        thread computes the same scalars, so all take the same branches."""
        grid = cuda.cg.this_grid()
        shared = cuda.shared.array(block, dtype=float64)
        first = cuda.grid(1)
        stride = cuda.gridsize(1)
        n = b.shape[0]
        a = 0.0
        c = 0.0
        e = 0.0
        coarse = blocks.shape[0] > 0
        for i in range(first, n, stride):
            ri = 0.0
            if diagonal[i] != 0.0:
                ri = b[i] - product(i, index, count, coefficient, diagonal, x)
            r[i] = ri
            if not coarse:
                zi = inverse_diagonal[i] * ri
                z[i] = zi
                d[i] = zi
                a += ri * zi
            c += ri * ri
            e += b[i] * b[i]
        if coarse:
            grid.sync()
            two_level(
                r, z, diagonal, inverse_diagonal, cell, start, member, shape, k, coarse_shape,
                to_coarse, blocks, inverse, cell_sums, coarse_r, coarse_partial, coarse_z,
            )  # fmt: skip
            for i in range(first, n, stride):
                d[i] = z[i]
                a += r[i] * z[i]
        slot = 0
        post(partial, slot, a, c, e, shared)
        grid.sync()
        rz = gathered(partial, slot, 0, shared)
        rr = gathered(partial, slot, 1, shared)
        bb = gathered(partial, slot, 2, shared)
        iterations = 0
        if bb == 0.0:  # nothing to solve: x = 0 (the CPU's CG too), no iteration
            for i in range(first, n, stride):
                x[i] = 0.0
            rr = 0.0
        limit = tolerance2 * bb
        while rr > limit and iterations < max_iterations:
            a = 0.0
            for i in range(first, n, stride):
                qi = 0.0
                if diagonal[i] != 0.0:
                    qi = product(i, index, count, coefficient, diagonal, d)
                q[i] = qi
                a += d[i] * qi
            slot = 1 - slot
            post(partial, slot, a, 0.0, 0.0, shared)
            grid.sync()
            curvature = gathered(partial, slot, 0, shared)
            if curvature == 0.0 or rz == 0.0:
                break  # the residual is exactly zero in exact arithmetic (as the CPU's CG)
            alpha = rz / curvature
            a = 0.0
            c = 0.0
            for i in range(first, n, stride):
                x[i] += alpha * d[i]
                ri = r[i] - alpha * q[i]
                r[i] = ri
                if not coarse:
                    zi = inverse_diagonal[i] * ri
                    z[i] = zi
                    a += ri * zi
                c += ri * ri
            if coarse:
                grid.sync()
                two_level(
                    r, z, diagonal, inverse_diagonal, cell, start, member, shape, k,
                    coarse_shape, to_coarse, blocks, inverse, cell_sums, coarse_r, coarse_partial,
                    coarse_z,
                )  # fmt: skip
                for i in range(first, n, stride):
                    a += r[i] * z[i]
            slot = 1 - slot
            post(partial, slot, a, c, 0.0, shared)
            grid.sync()
            rz_new = gathered(partial, slot, 0, shared)
            rr = gathered(partial, slot, 1, shared)
            iterations += 1
            if not math.isfinite(rr):
                break
            beta = rz_new / rz
            rz = rz_new
            for i in range(first, n, stride):
                d[i] = z[i] + beta * d[i]
            grid.sync()
        if first == 0:
            out[0] = iterations
            out[1] = rr
            out[2] = bb

    @cuda.jit
    def mark_wet(kind, alive, index, count, wet):
        """``wet`` 1 for live fluid particles and the walls in their lists (at r^k)."""
        i = cuda.grid(1)
        if i >= kind.shape[0] or not (alive[i] and kind[i] == fluid_kind):
            return
        wet[i] = 1
        for m in range(count[i]):
            j = index[m, i]
            if kind[j] == wall_kind:
                wet[j] = 1

    @cuda.jit
    def wet_rows(position, start, kind, alive, wet, margin, rows):
        """The rows of the list at r*, as :meth:`MPSSolver._wet`: the wet particles, or all
        live fluid and wall particles when some particle has moved more than ``margin``
        (``wet[n]``, set here by any thread that finds one, and read by the search)."""
        i = cuda.grid(1)
        n = kind.shape[0]
        if i >= n:
            return
        rows[i] = alive[i] and kind[i] != dummy_kind and wet[i] == 1
        if alive[i]:
            r2 = 0.0
            for k in range(position.shape[1]):
                d = position[i, k] - start[i, k]
                r2 += d * d
            if r2 > margin * margin:
                wet[n] = 1

    @cuda.jit
    def any_not_finite(vector, flag):
        i = cuda.grid(1)
        if i < vector.shape[0] and not math.isfinite(vector[i]):
            cuda.atomic.max(flag, 0, 1)

    @cuda.jit
    def fill(array, value):
        i = cuda.grid(1)
        if i < array.shape[0]:
            array[i] = value

    @cuda.jit
    def store_pressure(unknown, x, pressure):
        i = cuda.grid(1)
        if i < x.shape[0]:
            pressure[i] = max(x[i], 0.0) if unknown[i] == 1 else 0.0

    @cuda.jit
    def weighted_sums(values, start, index, weight, out):
        """out_k = sum over m in [start_k, start_k+1) of weight_m values[index_m], in m's order
        (the wall-pressure probes, Eq. F15): one thread a sum, a dozen terms each."""
        k = cuda.grid(1)
        if k < out.shape[0]:
            total = 0.0
            for m in range(start[k], start[k + 1]):
                total += weight[m] * values[index[m]]
            out[k] = total

    # ----------------------------------------------------------------------------- correction

    @cuda.jit(device=True)
    def solve_small(m, v, dim):
        """Cramer's rule for the symmetric moment matrix ``m`` (3x3, or 2x2 in its corner),
        in place in ``v``; unchanged when det < CORRECTION_MIN_DETERMINANT."""
        if dim == 2:
            a = m[0, 0]
            bb = m[0, 1]
            dd = m[1, 1]
            det = a * dd - bb * bb
            if det < min_det:
                return
            x = (dd * v[0] - bb * v[1]) / det
            y = (a * v[1] - bb * v[0]) / det
            v[0] = x
            v[1] = y
            return
        c00 = m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]
        c01 = m[1, 2] * m[2, 0] - m[1, 0] * m[2, 2]
        c02 = m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]
        det = m[0, 0] * c00 + m[0, 1] * c01 + m[0, 2] * c02
        if det < min_det:
            return
        c11 = m[0, 0] * m[2, 2] - m[0, 2] * m[2, 0]
        c12 = m[0, 2] * m[1, 0] - m[0, 0] * m[1, 2]
        c22 = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
        v0 = v[0]
        v1 = v[1]
        v2 = v[2]
        v[0] = (c00 * v0 + c01 * v1 + c02 * v2) / det
        v[1] = (c01 * v0 + c11 * v1 + c12 * v2) / det
        v[2] = (c02 * v0 + c12 * v1 + c22 * v2) / det

    @cuda.jit
    def lowest_pressure(pressure, kind, alive, index, distance, count, re, lowest):
        """p_min,i of Eq. (F10c): the least pressure of i and its live fluid and wall neighbours
        within r_e (its own where it has no row)."""
        i = cuda.grid(1)
        if i >= pressure.shape[0]:
            return
        least = pressure[i]
        if alive[i]:
            for m in range(count[i]):
                j = index[m, i]
                if distance[m, i] < re and kind[j] != dummy_kind and alive[j]:
                    least = min(least, pressure[j])
        lowest[i] = least

    @cuda.jit
    def correct(
        position, velocity, pressure, kind, alive, index, distance, count, re, re_lap,
        n0_gradient, coefficient, dt, corrected, conservative, lowest, repulse, unknown,
        out_position, out_velocity,
    ):  # fmt: skip
        """Eq. (F10), (F10a), (F10b) or (F10c) and the correction Eq. (F13)."""
        i = cuda.grid(1)
        if i >= position.shape[0]:
            return
        dim = position.shape[1]
        for k in range(dim):
            out_velocity[i, k] = velocity[i, k]
            out_position[i, k] = position[i, k]
        if not (alive[i] and kind[i] == fluid_kind):
            return
        gradient = cuda.local.array(3, dtype=float64)
        for k in range(3):
            gradient[k] = 0.0
        if conservative:
            for m in range(count[i]):
                j = index[m, i]
                r = distance[m, i]
                if r >= re or kind[j] == dummy_kind or not alive[j]:
                    continue
                excess = (pressure[i] + pressure[j]) - (lowest[i] + lowest[j])
                scale = excess / (r * r) * weight(r, re)
                for k in range(dim):
                    gradient[k] += scale * (position[j, k] - position[i, k])
        else:
            least = pressure[i]
            for m in range(count[i]):
                j = index[m, i]
                if distance[m, i] < re and kind[j] != dummy_kind:
                    least = min(least, pressure[j])
            for m in range(count[i]):
                j = index[m, i]
                r = distance[m, i]
                if r >= re or kind[j] == dummy_kind:
                    continue
                scale = (pressure[j] - least) / (r * r) * weight(r, re)
                for k in range(dim):
                    gradient[k] += scale * (position[j, k] - position[i, k])
            if corrected:
                moments = cuda.local.array((3, 3), dtype=float64)
                for k in range(3):
                    for s in range(3):
                        moments[k, s] = 0.0
                for m in range(count[i]):
                    j = index[m, i]
                    r = distance[m, i]
                    if r >= re or kind[j] == dummy_kind:
                        continue
                    w = weight(r, re) / (r * r)
                    for k in range(dim):
                        for s in range(dim):
                            dk = position[j, k] - position[i, k]
                            moments[k, s] += w * dk * (position[j, s] - position[i, s])
                for k in range(dim):
                    for s in range(dim):
                        moments[k, s] *= dim / n0_gradient
                solve_small(moments, gradient, dim)
            if repulse and unknown[i] == 0:
                highest = pressure[i]
                push = cuda.local.array(3, dtype=float64)
                normal = cuda.local.array(3, dtype=float64)
                for k in range(3):
                    push[k] = 0.0
                    normal[k] = 0.0
                for m in range(count[i]):
                    j = index[m, i]
                    r = distance[m, i]
                    if kind[j] == dummy_kind or r >= re_lap or r == 0.0:
                        continue
                    w = weight(r, re_lap) / r
                    for k in range(dim):
                        normal[k] -= w * (position[j, k] - position[i, k])
                    if r < re:
                        if kind[j] == fluid_kind:
                            highest = max(highest, pressure[j])
                        w = weight(r, re) / (r * r)
                        for k in range(dim):
                            push[k] += w * (position[j, k] - position[i, k])
                size2 = 0.0
                along = 0.0
                for k in range(dim):
                    size2 += normal[k] * normal[k]
                    along += push[k] * normal[k]
                if size2 != 0.0:
                    along /= size2
                    for k in range(dim):
                        gradient[k] += (highest - pressure[i]) * (push[k] - along * normal[k])
        for k in range(dim):
            du = coefficient * gradient[k]
            out_velocity[i, k] += du
            out_position[i, k] += dt * du

    @cuda.jit
    def escape(position, velocity, pressure, kind, alive, lower, upper, dead):
        """Live fluid particles outside the domain or no longer finite die; ``dead[0]`` counts
        them (an integer sum: the same whatever the order)."""
        i = cuda.grid(1)
        if i >= position.shape[0] or not (alive[i] and kind[i] == fluid_kind):
            return
        dying = False
        for k in range(position.shape[1]):
            x = position[i, k]
            u = velocity[i, k]
            if not (math.isfinite(x) and math.isfinite(u)) or x < lower[k] or x > upper[k]:
                dying = True
        if dying:
            alive[i] = False
            cuda.atomic.add(dead, 0, 1)
            pressure[i] = 0.0
            for k in range(position.shape[1]):
                velocity[i, k] = 0.0

    @cuda.jit
    def extent(position, velocity, kind, alive, axis, out):
        """out = (largest speed^2, largest and minus the least coordinate along ``axis``, live
        fluid count) over live fluid particles (maxima: the same whatever the order)."""
        i = cuda.grid(1)
        if i >= position.shape[0] or not (alive[i] and kind[i] == fluid_kind):
            return
        speed2 = 0.0
        along = 0.0
        for k in range(position.shape[1]):
            speed2 += velocity[i, k] * velocity[i, k]
            along += position[i, k] * axis[k]
        cuda.atomic.max(out, 0, speed2)
        cuda.atomic.max(out, 1, along)
        cuda.atomic.max(out, 2, -along)
        cuda.atomic.add(out, 3, 1.0)

    return {name: value for name, value in locals().items() if callable(value)}


def _grid(n: int) -> int:
    return max(1, (n + BLOCK - 1) // BLOCK)


class GPUSolver:
    """An MPS fluid on the GPU with :class:`~jellysim.fluid.mps.MPSSolver`'s interface: the
    state lives on the GPU; ``position``, ``velocity``, ``pressure``, ``number_density``,
    ``alive`` read host copies (made once after each step), and :meth:`restore` writes it."""

    device = "cuda"

    def __init__(self, params: MPSParameters, positions: np.ndarray, kinds: np.ndarray) -> None:
        reason = unavailable()
        if reason is not None:
            raise RuntimeError(reason)
        quiet_small_grid_warnings()
        self._cuda = cuda
        self.k = _kernels()
        setup = solver_setup(params, positions, kinds)
        positions = setup.positions
        self.params = p = params
        l0, dim = p.l0, p.dim
        self.reference = setup.reference
        self.constants = setup.constants
        self.search_radius = setup.search_radius
        n = positions.shape[0]
        self.n = n
        self.kind = setup.kind
        self.time = 0.0
        self.searches = 0
        self.domain_min = setup.domain_min
        self.domain_max = setup.domain_max
        # The cell grid, cells as wide as the search radius, over the particles' initial box
        # and a cell around it: a particle beyond it counts in the nearest cell on its edge
        # (clamping keeps two particles within the radius in neighbouring cells, so no pair
        # is missed; the domain around the tank, where splashes die, needs no cells of its own).
        cell = self.search_radius
        low = positions.min(axis=0) - cell
        high = positions.max(axis=0) + cell
        shape = np.ones(3, dtype=np.int64)
        shape[:dim] = np.floor((high - low) / cell).astype(np.int64) + 1
        self._shape = shape
        self._cells = int(np.prod(shape))
        lower = np.zeros(3)
        lower[:dim] = low
        on_lattice = lattice_reference(dim, l0, p.neighbour_radius, p.lattice).count
        self.width = int(math.ceil(WIDTH_FACTOR * on_lattice)) + 8
        d = cuda.to_device
        self._d_position = d(positions)
        self._d_velocity = d(np.zeros((n, dim)))
        self._d_pressure = d(np.zeros(n))
        self._d_density = d(np.zeros(n))
        self._d_start_density = d(np.zeros(n))
        self._d_alive = d(np.ones(n, dtype=np.bool_))
        self._d_kind = d(self.kind)
        self._d_lower = d(lower)
        self._d_shape = d(shape)
        self._d_domain_min = d(self.domain_min)
        self._d_domain_max = d(self.domain_max)
        self._d_gravity = d(p.gravity_vector)
        g = p.gravity_vector
        axis = g / np.linalg.norm(g) if np.any(g) else np.eye(dim)[-1]
        self._d_axis = d(np.ascontiguousarray(axis))
        da = cuda.device_array
        self._scratch_position = da((n, dim))
        self._scratch_velocity = da((n, dim))
        self._start_position = da((n, dim))
        self._external = da((1, dim))
        self._cell = da(n, dtype=np.int64)
        self._count = da(self._cells, dtype=np.int32)
        self._cursor = da(self._cells, dtype=np.int32)
        self._start = da(self._cells + 1, dtype=np.int32)
        self._tile_sums = da(_grid(self._cells), dtype=np.int32)
        self._tile_offsets = da(_grid(self._cells), dtype=np.int32)
        self._member = da(n, dtype=np.int64)
        self._within = da(n, dtype=np.int32)
        self._unknown = da(n, dtype=np.int8)
        self._rows_all = d((self.kind != DUMMY).astype(np.bool_))
        self._rows = da(n, dtype=np.bool_)
        self._wet = da(n + 1, dtype=np.int8)  # the last: 1 for every row (the first search)
        self._most = da(1, dtype=np.int64)
        # the PPE's rows and the CG's vectors, over all particles (0 off the unknowns)
        self._diagonal, self._inverse_diagonal = da(n), da(n)
        self._b, self._x, self._r, self._z, self._q = da(n), da(n), da(n), da(n), da(n)
        self._d0 = da(n)
        self._lowest = da(n)
        self._partial = da((2, _grid(n), 3))  # the CG's block sums, two slots
        self._solve_out = da(3)
        self._flag = da(1, dtype=np.int32)
        self._dead = cuda.to_device(np.zeros(1, dtype=np.int64))  # dead particles so far
        self._cg_blocks = 0  # the cooperative grid's blocks, found at the first solve
        self._extent = da(4)
        self._allocate_lists(self.width)
        self._host: dict[str, np.ndarray] = {}
        # the coarse space (fluid.solver = "deflated"): none until the first solve makes it
        self.two_level = p.solver == "deflated"
        self._coarse_base = max(1, round(p.coarse_cell * l0 / self.search_radius))
        self._coarse_k = self._coarse_base
        self._coarse_age = COARSE_REFRESH  # steps since E^-1 was made: make it at once
        self._coarse_baseline = 0  # the iterations of the first solve with this E^-1
        self._coarse = no_coarse_space()
        self.coarse_aggregates = 0

    # -------------------------------------------------------------------------- host views

    def _download(self, name: str, array: Any) -> np.ndarray:
        """The host copy of a state array, made once after each step; read-only, since a
        write to it would not reach the GPU (:meth:`restore` writes the state)."""
        if name not in self._host:
            copy = array.copy_to_host()
            copy.setflags(write=False)
            self._host[name] = copy
        return self._host[name]

    @property
    def position(self) -> np.ndarray:
        return self._download("position", self._d_position)

    @property
    def device_position(self) -> Any:
        """The positions (N, D) m on the GPU, for kernels beside the solver's (the soft bell's
        springs): read them, write only through :meth:`restore`."""
        return self._d_position

    @property
    def device_velocity(self) -> Any:
        """The velocities (N, D) m/s on the GPU, as :attr:`device_position`."""
        return self._d_velocity

    @property
    def velocity(self) -> np.ndarray:
        return self._download("velocity", self._d_velocity)

    @property
    def pressure(self) -> np.ndarray:
        return self._download("pressure", self._d_pressure)

    @property
    def number_density(self) -> np.ndarray:
        return self._download("number_density", self._d_density)

    @property
    def alive(self) -> np.ndarray:
        return self._download("alive", self._d_alive)

    # ------------------------------------------------------------------------------- probes

    def pressure_gauge(
        self, rows: Sequence[np.ndarray], weights: Sequence[np.ndarray]
    ) -> Callable[[], np.ndarray]:
        """As :meth:`MPSSolver.pressure_gauge`, the sums taken on the GPU: ``rows`` and
        ``weights`` are uploaded once (concatenated, with each sum's start), and each call
        launches one thread a sum and downloads the K sums, not the N pressures."""
        sums = len(rows)
        if [len(r) for r in rows] != [len(w) for w in weights]:
            raise ValueError("each sum needs as many weights as rows")
        if sums == 0:
            return lambda: np.zeros(0)
        start = np.zeros(sums + 1, dtype=np.int64)
        start[1:] = np.cumsum([len(r) for r in rows])
        d = self._cuda.to_device
        index = d(np.concatenate(rows).astype(np.int64))
        weight = d(np.concatenate(weights).astype(np.float64))
        d_start, out = d(start), self._cuda.device_array(sums)
        kernel = self.k["weighted_sums"][_grid(sums), BLOCK]

        def gauge() -> np.ndarray:
            kernel(self._d_pressure, d_start, index, weight, out)
            return out.copy_to_host()

        return gauge

    # --------------------------------------------------------------------------- neighbours

    def _allocate_lists(self, width: int) -> None:
        da = self._cuda.device_array
        self.width = width
        # slot-major (width, N): the threads of a warp read neighbouring addresses
        self._index = da((width, self.n), dtype=np.int32)
        self._distance = da((width, self.n))
        self._coefficient = da((width, self.n))
        self._list_count = da(self.n, dtype=np.int32)

    def _search(self, position: Any, rows: Any, every: Any) -> None:
        """The neighbour lists at ``position`` for the particles of ``rows`` (all live walls
        and fluid particles where ``every[-1]`` is 1)."""
        k, g = self.k, _grid(self.n)
        self.searches += 1
        cells = _grid(self._cells)
        k["fill"][cells, BLOCK](self._count, 0)
        k["fill"][cells, BLOCK](self._cursor, 0)
        k["cell_of"][g, BLOCK](
            position, self._d_alive, self._d_lower, 1.0 / self.search_radius, self._d_shape,
            self._cell, self._count,
        )  # fmt: skip
        tiles = _grid(self._cells)
        k["tile_sums"][tiles, BLOCK](self._count, self._tile_sums)
        k["tile_offsets"][1, BLOCK](self._tile_sums, self._tile_offsets)
        k["scan_tiles"][tiles, BLOCK](self._count, self._tile_offsets, self._start)
        k["scatter"][g, BLOCK](self._cell, self._start, self._cursor, self._member)
        k["sort_cells"][_grid(self._cells), BLOCK](self._start, self._member)
        while True:
            k["fill"][1, BLOCK](self._most, 0)
            k["search"][g, BLOCK](
                position, rows, every, self._d_kind, self._cell, self._start, self._member,
                self._d_shape, self.search_radius, self._index, self._distance, self._list_count,
                self._most,
            )  # fmt: skip
            most = int(self._most.copy_to_host()[0])
            if most <= self.width:
                return
            self._allocate_lists(int(most * 1.25) + 8)

    # --------------------------------------------------------------------------------- step

    def begin_frame(self) -> None:
        """The coarse space (fluid.solver = "deflated") is made anew at a frame's first solve,
        as after :meth:`restore`: a run resumed from a frame's checkpoint then solves with the
        E^-1 the run itself had, to the bit."""
        self._coarse_age = COARSE_REFRESH

    def stable_dt(self, external_acceleration: float = 0.0) -> float:
        """As :meth:`MPSSolver.stable_dt`, the maxima taken on the GPU."""
        p = self.params
        self._extent.copy_to_device(np.array([0.0, -np.inf, -np.inf, 0.0]))
        self.k["extent"][_grid(self.n), BLOCK](
            self._d_position, self._d_velocity, self._d_kind, self._d_alive, self._d_axis,
            self._extent,
        )  # fmt: skip
        speed2, high, minus_low, fluid = self._extent.copy_to_host()
        speed = height = None
        if fluid > 0:
            speed = math.sqrt(speed2)
            height = float(high + minus_low) + p.l0
        return min(step_limits(p, speed, height, external_acceleration).values(), default=math.inf)

    def step(self, dt: float, external_force: Any = None) -> StepStats:
        """Advance the fluid by ``dt`` (s) on the GPU, as :meth:`MPSSolver.step`;
        ``external_force`` (N, D) N/m3 is a host array (uploaded) or a device array (read
        where it is)."""
        p = self.params
        k, n, g = self.k, self.n, _grid(self.n)
        if external_force is not None and external_force.shape != (n, p.dim):
            # the kernel reads row i of it, unchecked
            raise ValueError(f"external_force must be ({n}, {p.dim}), not {external_force.shape}")
        self._host.clear()
        stats = StepStats()
        timer = PhaseTimer(stats.seconds)
        ref_nd = self.reference["number_density"]
        ref_lap = self.reference["laplacian"]
        ref_grad = self.reference["gradient"]
        re_nd = p.re_number_density * p.l0
        re_grad = p.re_gradient * p.l0
        re_lap = p.laplacian_radius * p.l0
        dim = p.dim
        mixed = p.source == "mixed"
        sync = self._cuda.synchronize
        with timer("neighbours"):
            self._search(self._d_position, self._rows_all, self._wet)
            k["fill"][_grid(n + 1), BLOCK](self._wet, 0)
            k["mark_wet"][g, BLOCK](
                self._d_kind, self._d_alive, self._index, self._list_count, self._wet
            )
            if mixed:
                k["number_density"][g, BLOCK](
                    self._index, self._distance, self._list_count, re_nd,
                    self._d_start_density, self._within,
                )  # fmt: skip
            sync()
        with timer("explicit"):
            self._start_position.copy_to_device(self._d_position)
            has_external = external_force is not None
            external = self._external
            if has_external and hasattr(external_force, "copy_to_host"):
                external = external_force  # already on the GPU (the soft bell's springs)
            elif has_external:
                force = np.ascontiguousarray(external_force, dtype=np.float64)
                if self._external.shape != force.shape:
                    self._external = self._cuda.to_device(force)
                else:
                    self._external.copy_to_device(force)
                external = self._external
            viscous = p.kinematic_viscosity * 2.0 * dim / (ref_lap.lambda_ * ref_lap.n0)
            k["explicit_stage"][g, BLOCK](
                self._d_position, self._d_velocity, self._d_kind, self._d_alive, self._index,
                self._distance, self._list_count, re_lap, viscous, self._d_gravity,
                external, has_external, p.density, dt, self._scratch_position,
                self._scratch_velocity,
            )  # fmt: skip
            k["collision"][g, BLOCK](
                self._scratch_position, self._scratch_velocity, self._d_kind, self._d_alive,
                self._index, self._list_count, p.collision_distance * p.l0,
                0.5 * (1.0 + p.collision_restitution), dt, self._d_position, self._d_velocity,
            )  # fmt: skip
            sync()
        with timer("neighbours"):
            # rows at r*: the fluid and the walls it reached at r^k (MPSSolver._wet)
            margin = self.search_radius - re_nd
            k["wet_rows"][g, BLOCK](
                self._d_position, self._start_position, self._d_kind, self._d_alive, self._wet,
                margin, self._rows,
            )  # fmt: skip
            self._search(self._d_position, self._rows, self._wet)
            k["number_density"][g, BLOCK](
                self._index, self._distance, self._list_count, re_nd, self._d_density,
                self._within,
            )  # fmt: skip
            sync()
        with timer("assembly"):
            threshold = p.beta * ref_nd.n0
            k["fill"][1, BLOCK](self._most, 0)  # the free-surface count, this time
            k["classify"][g, BLOCK](
                self._d_alive, self._d_kind, self._d_density, self._d_start_density,
                self._within, threshold, p.surface == "neighbour-count",
                p.surface_neighbour_threshold * ref_nd.count,
                p.surface == "either-density" and mixed, self._unknown, self._most,
            )  # fmt: skip
            k["assemble"][g, BLOCK](
                self._d_position, self._d_velocity, self._d_kind, self._d_alive, self._index,
                self._distance, self._list_count, self._unknown, re_lap,
                2.0 * dim / (ref_lap.lambda_ * ref_lap.n0), p.density * p.compressibility / dt**2,
                re_grad, dim / ref_grad.n0, mixed,
                p.density / dt if mixed else p.density / dt**2,
                p.mixed_relaxation * p.density / dt**2, ref_nd.n0, self._d_density,
                self._d_start_density, self._d_pressure, self._coefficient, self._diagonal,
                self._inverse_diagonal, self._b, self._x,
            )  # fmt: skip
            stats.surface = int(self._most.copy_to_host()[0])
        with timer("solve"):
            stats.iterations, stats.residual = self._solve()
            k["store_pressure"][g, BLOCK](self._unknown, self._x, self._d_pressure)
            sync()
        with timer("correction"):
            conservative = p.gradient == "conservative"
            if conservative:
                k["lowest_pressure"][g, BLOCK](
                    self._d_pressure, self._d_kind, self._d_alive, self._index, self._distance,
                    self._list_count, re_grad, self._lowest,
                )  # fmt: skip
            k["correct"][g, BLOCK](
                self._d_position, self._d_velocity, self._d_pressure, self._d_kind,
                self._d_alive, self._index, self._distance, self._list_count, re_grad, re_lap,
                ref_grad.n0, -dt * dim / (ref_grad.n0 * p.density), dt,
                p.gradient == "corrected", conservative, self._lowest, p.surface_repulsion,
                self._unknown, self._scratch_position, self._scratch_velocity,
            )  # fmt: skip
            self._d_position.copy_to_device(self._scratch_position)
            self._d_velocity.copy_to_device(self._scratch_velocity)
            self.time += dt
            k["escape"][g, BLOCK](
                self._d_position, self._d_velocity, self._d_pressure, self._d_kind,
                self._d_alive, self._d_domain_min, self._d_domain_max, self._dead,
            )  # fmt: skip
            sync()
            stats.dead = int(self._dead.copy_to_host()[0])  # not the whole alive array
        return stats

    def _solve(self) -> tuple[int, float]:
        """Jacobi-preconditioned CG on the assembled rows, warm-started from the last
        pressure, in one cooperative launch; the answer in ``_x``. Raises FluidDiverged as
        the CPU path does."""
        p = self.params
        if self.two_level and self._coarse_age >= COARSE_REFRESH:
            self._make_coarse_space()
        args = (
            self._index, self._list_count, self._coefficient, self._diagonal,
            self._inverse_diagonal, self._b, self._x, self._r, self._z, self._d0, self._q,
            self._partial, p.tolerance**2, p.max_iterations, self._solve_out, *self._coarse,
        )  # fmt: skip
        kernel = self.k["conjugate_gradient"]
        if self._cg_blocks == 0:
            self._cg_blocks = cooperative_blocks(kernel, args, _grid(self.n))
        kernel[self._cg_blocks, BLOCK](*args)
        iterations, rr, bb = self._solve_out.copy_to_host()
        if self.two_level:
            self._coarse_age += 1
            if self._coarse_age == 1:
                self._coarse_baseline = int(iterations)
            elif iterations > COARSE_STALE * self._coarse_baseline + 2:
                self._coarse_age = COARSE_REFRESH  # stale: a new E^-1 for the next solve
        # a non-finite b (NaN or inf) gives a non-finite residual, as on the CPU
        residual = 0.0 if bb == 0.0 else math.sqrt(rr / bb)
        if not (residual <= p.tolerance) or not self._finite(self._x):
            raise FluidDiverged(
                f"pressure solve stopped at relative residual {residual:.3g} after "
                f"{int(iterations)} iterations (tolerance {p.tolerance:.3g}); reduce the time "
                "step",
                time=self.time,
                iterations=int(iterations),
                residual=residual,
            )
        return int(iterations), residual

    def _make_coarse_space(self) -> None:
        """The aggregates of the current unknowns and E^-1 (m x m) on the GPU: which blocks of
        search cells hold unknown rows (the blocks grown from ``coarse_cell`` while there are
        too many), E = Z^T A Z summed on the GPU, factored and inverted on the host
        (Cholesky; E is symmetric positive definite as A is). Until the next, the aggregates
        are these; rows in a block that had no unknown then get Jacobi alone."""
        k, cuda_ = self.k, self._cuda
        shape = self._shape
        # from the base size each time: the aggregates are a function of this state alone, so
        # a resumed run makes the ones the run made
        self._coarse_k = self._coarse_base
        while True:
            size = self._coarse_k
            coarse_shape = np.ones(3, dtype=np.int64)
            coarse_shape[:] = (shape + size - 1) // size
            cells = int(np.prod(coarse_shape))
            flags = cuda_.to_device(np.zeros(cells, dtype=np.int32))
            d_coarse_shape = cuda_.to_device(coarse_shape)
            k["coarse_flags"][_grid(self.n), BLOCK](
                self._cell, self._diagonal, self._d_shape, size, d_coarse_shape, flags
            )
            blocks = np.flatnonzero(flags.copy_to_host()).astype(np.int64)
            if len(blocks) <= min(COARSE_LARGEST, max(1, self.n // COARSE_PARTICLES)):
                break
            self._coarse_k += 1
        self._coarse_age = 0
        m = len(blocks)
        if m == 0:
            self._coarse = no_coarse_space()
            self.coarse_aggregates = 0
            return
        to_coarse = np.full(cells, -1, dtype=np.int32)
        to_coarse[blocks] = np.arange(m, dtype=np.int32)
        d = cuda_.to_device
        d_to_coarse, d_blocks = d(to_coarse), d(blocks)
        e = cuda_.device_array((m, m))
        k["fill"][_grid(m * m), BLOCK](e.reshape(m * m), 0.0)
        k["coarse_matrix"][_grid(m), BLOCK](
            self._cell, self._start, self._member, self._index, self._list_count,
            self._coefficient, self._diagonal, self._d_shape, size, d_coarse_shape, d_to_coarse,
            d_blocks, e,
        )  # fmt: skip
        matrix = e.copy_to_host()
        info = -1
        if np.all(np.isfinite(matrix)):  # LAPACK's Cholesky factor, then the inverse from it
            factor, info = scipy.linalg.lapack.dpotrf(matrix, lower=1)
            if info == 0:
                lower, info = scipy.linalg.lapack.dpotri(factor, lower=1)
        if info != 0:  # not positive definite, or not finite: Jacobi alone
            log.warning("coarse space of %d aggregates dropped (LAPACK %d): Jacobi alone", m, info)
            self._coarse = no_coarse_space()
            self.coarse_aggregates = 0
            return
        # the lower triangle mirrored: E^-1 exactly symmetric, the preconditioner SPD
        inverse = np.tril(lower) + np.tril(lower, -1).T
        da = cuda_.device_array
        self._coarse = (
            self._cell, self._start, self._member, self._d_shape, size, d_coarse_shape,
            d_to_coarse, d_blocks, d(np.ascontiguousarray(inverse)), da(self._cells), da(m),
            da((COARSE_CHUNKS, m)), da(m),
        )  # fmt: skip
        self.coarse_aggregates = m

    def _finite(self, vector: Any) -> bool:
        """Whether every entry of the device vector is finite (one reduction, read back)."""
        self.k["fill"][1, BLOCK](self._flag, 0)
        self.k["any_not_finite"][_grid(self.n), BLOCK](vector, self._flag)
        return int(self._flag.copy_to_host()[0]) == 0

    # ---------------------------------------------------------------------------- checkpoints

    def state_arrays(self) -> dict[str, np.ndarray]:
        """Host copies of the state, the same names as :meth:`MPSSolver.state_arrays` (no
        Verlet list: the GPU searches every step), so a checkpoint resumes on either device."""
        return {
            "position": self.position.copy(),
            "velocity": self.velocity.copy(),
            "pressure": self.pressure.copy(),
            "number_density": self.number_density.copy(),
            "alive": self.alive.copy(),
            "kind": self.kind.copy(),
            "time": np.array(self.time),
        }

    def restore(self, arrays: dict[str, np.ndarray]) -> None:
        """Load a state (from either device's :meth:`state_arrays`) onto the GPU."""
        targets = {
            "position": self._d_position,
            "velocity": self._d_velocity,
            "pressure": self._d_pressure,
            "number_density": self._d_density,
            "alive": self._d_alive,
        }
        values = {}
        for name, target in targets.items():  # every shape checked before anything is written
            values[name] = np.ascontiguousarray(arrays[name], dtype=target.dtype)
            if values[name].shape != target.shape:
                raise ValueError(f"{name}: shape {values[name].shape}, expected {target.shape}")
        if arrays["kind"].shape != self.kind.shape:
            raise ValueError(f"kind: shape {arrays['kind'].shape}, expected {self.kind.shape}")
        for name, target in targets.items():
            target.copy_to_device(values[name])
        self._dead.copy_to_device(np.array([np.count_nonzero(~values["alive"])], dtype=np.int64))
        self.kind[:] = arrays["kind"]
        self._d_kind.copy_to_device(self.kind)
        self._rows_all.copy_to_device((self.kind != DUMMY).astype(np.bool_))
        self.time = float(arrays["time"])
        self._host.clear()
        self._coarse_age = COARSE_REFRESH  # the coarse space of the restored state, next solve


_NO_COARSE: tuple[Any, ...] | None = None


def no_coarse_space() -> tuple[Any, ...]:
    """The coarse-space arguments of the CG kernel for Jacobi alone (no aggregates): arrays of
    the types a coarse space has, made once."""
    global _NO_COARSE
    if _NO_COARSE is None:
        d = cuda.to_device
        _NO_COARSE = (
            d(np.full(1, -1, dtype=np.int64)), d(np.zeros(2, dtype=np.int32)),
            d(np.zeros(1, dtype=np.int64)), d(np.ones(3, dtype=np.int64)), 1,
            d(np.ones(3, dtype=np.int64)), d(np.full(1, -1, dtype=np.int32)),
            d(np.zeros(0, dtype=np.int64)), d(np.zeros((1, 1))), d(np.zeros(1)), d(np.zeros(1)),
            d(np.zeros((COARSE_CHUNKS, 1))), d(np.zeros(1)),
        )  # fmt: skip
    return _NO_COARSE


def cooperative_blocks(kernel: Any, args: tuple[Any, ...], wanted: int) -> int:
    """The blocks of a cooperative launch of ``kernel`` with ``args``: ``wanted``, or as many
    as the GPU holds at once if fewer (one in the simulator, whose grid barrier holds within
    a block only)."""
    if simulated():
        return 1
    import numba

    try:
        compiled = kernel.compile(tuple(numba.typeof(a) for a in args))
        most = int(compiled.max_cooperative_grid_blocks(BLOCK))
    except Exception as error:  # noqa: BLE001 - measured on numba-cuda 0.30; others may differ
        # two blocks of BLOCK threads a multiprocessor fit whatever the kernel's registers
        most = 2 * int(cuda.get_current_device().MULTIPROCESSOR_COUNT)
        log.warning("the CG's cooperative grid: %s; using %d blocks", error, most)
    return max(1, min(wanted, most))


def solver_on_gpu(params: MPSParameters, positions: np.ndarray, kinds: np.ndarray) -> GPUSolver:
    """A :class:`GPUSolver`, or InputError saying what to install where no GPU can run it."""
    reason = unavailable()
    if reason is not None:
        from jellysim.errors import InputError

        raise InputError(reason)
    return GPUSolver(params, positions, kinds)


__all__ = [
    "BLOCK",
    "GPUSolver",
    "no_coarse_space",
    "quiet_small_grid_warnings",
    "simulated",
    "solver_on_gpu",
    "unavailable",
]
