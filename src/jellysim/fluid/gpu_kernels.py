"""The MPS fluid's CUDA kernels (Numba), for :class:`jellysim.fluid.gpu.GPUSolver`: module-level
functions, so that Numba caches each kernel's machine code (``cache=True``: compiled on a
machine's first run, loaded from ``__pycache__`` or ``NUMBA_CACHE_DIR`` after; as closures they
were compiled again by every run, 10-15 s of a GPU run). Device functions are compiled into the
kernels that call them. Imported on the first GPU solver (:func:`jellysim.fluid.gpu._kernels`);
the equations and the summation orders are :mod:`jellysim.fluid.gpu`'s docstring's.
"""

import math

from numba import cuda, float32, float64, int32

# The constants the kernels read, written here and not imported: Numba compiles a global's value
# into the machine code and throws a cached kernel away only when the kernel's own file changes,
# so a value imported from another module could change under a stale cache. A unit test
# (tests/unit/test_fluid_gpu.py) holds them equal to their sources.
BLOCK = 128  # jellysim.fluid.gpu.BLOCK: threads of a block
CELLS_PER_RADIUS = 2  # jellysim.fluid.neighbours': search cells radius / 2 wide
FLUID, WALL, DUMMY = 0, 1, 2  # jellysim.fluid.geometry's particle kinds
CORRECTION_MIN_DETERMINANT = 0.3  # jellysim.fluid.kernels'
# a step's counters (an int64 array): the free-surface particles of the step, the dead so far
SURFACE, DEAD = 0, 1


@cuda.jit(device=True)
def weight(r, re):
    if r < re:
        return re / r - 1.0
    return 0.0


@cuda.jit(device=True)
def team_sum(shared, value, team):
    """The sum of ``value`` over each team of ``team`` consecutive threads of the block (a
    power of two dividing BLOCK), in a fixed tree order (every thread of a team gets its
    team's sum)."""
    t = cuda.threadIdx.x
    lane = t % team
    shared[t] = value
    cuda.syncthreads()
    step = team // 2
    while step > 0:
        if lane < step:
            shared[t] += shared[t + step]
        cuda.syncthreads()
        step //= 2
    total = shared[t - lane]
    cuda.syncthreads()
    return total


@cuda.jit(device=True)
def block_sum(shared, value):
    """The sum of ``value`` over the block, in a fixed tree order (every thread gets it)."""
    return team_sum(shared, value, BLOCK)


# ------------------------------------------------------------------------ neighbour search


@cuda.jit(device=True)
def cell_coordinate(x, lower, inverse, size):
    c = int(math.floor((x - lower) * inverse))
    if c < 0:
        return 0
    if c >= size:
        return size - 1
    return c


@cuda.jit(device=True)
def cell_of(i, position, alive, lower, inverse, shape, cell, count):
    """Particle i's search cell (-1 when it is dead), counted in ``count``."""
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
    while offset < BLOCK:
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


@cuda.jit(device=True)
def tile_offsets(sums, offsets, shared):
    """``offsets[b]``: the cells before tile b (by one block, a chunk of tiles at a time)."""
    t = cuda.threadIdx.x
    carry = 0
    for first in range(0, sums.shape[0], BLOCK):
        b = first + t
        own = sums[b] if b < sums.shape[0] else 0
        inclusive = block_scan(shared, own)
        if b < sums.shape[0]:
            offsets[b] = carry + inclusive - own
        if t == BLOCK - 1:  # the chunk's total, to every thread
            shared[0] = inclusive
        cuda.syncthreads()
        carry += shared[0]
        cuda.syncthreads()


@cuda.jit(device=True)
def scatter(i, cell, start, cursor, member):
    c = cell[i]
    if c >= 0:
        member[start[c] + cuda.atomic.add(cursor, c, 1)] = i


@cuda.jit(device=True)
def sort_cell(c, start, member):
    """Cell c's members in particle order (the scatter's order is the atomics')."""
    for a in range(start[c] + 1, start[c + 1]):
        value = member[a]
        b = a - 1
        while b >= start[c] and member[b] > value:
            member[b + 1] = member[b]
            b -= 1
        member[b + 1] = value


@cuda.jit(device=True)
def sorted_positions(m, start, member, position, member_position):
    """Member slot m's coordinates, copied in cell order (``member_position`` (D, N))."""
    if m < start[start.shape[0] - 1]:
        j = member[m]
        for k in range(position.shape[1]):
            member_position[k, m] = position[j, k]


@cuda.jit(device=True)
def search(
    i, position, rows, every, kind, cell, start, member, member_position, shape, radius,
    index, distance, count, most,
):  # fmt: skip
    """Row i (``rows[i]``, or every live fluid and wall particle where ``every[-1]`` is 1):
    the live particles within ``radius`` of particle i but itself. The cells are radius /
    CELLS_PER_RADIUS wide; row i scans those within CELLS_PER_RADIUS of its own along each
    axis, each (y, z) row of them one run of members along x, in cell order then particle
    order, reading the members' coordinates copied in that order (``member_position``) and
    their indices only for those within the radius."""
    found = 0
    width = index.shape[0]
    c = cell[i]
    row = rows[i] or (every[every.shape[0] - 1] == 1 and kind[i] != DUMMY)
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
        x0 = max(cx - CELLS_PER_RADIUS, 0)
        x1 = min(cx + CELLS_PER_RADIUS, shape[0] - 1)
        z0 = 0
        z1 = 0
        if dim == 3:
            z0 = max(cz - CELLS_PER_RADIUS, 0)
            z1 = min(cz + CELLS_PER_RADIUS, shape[2] - 1)
        for z in range(z0, z1 + 1):
            for y in range(max(cy - CELLS_PER_RADIUS, 0), min(cy + CELLS_PER_RADIUS + 1, shape[1])):
                run = shape[0] * (y + shape[1] * z)
                for m in range(start[run + x0], start[run + x1 + 1]):
                    dx = member_position[0, m] - xi
                    dy = member_position[1, m] - yi
                    r2 = dx * dx + dy * dy
                    if dim == 3:
                        dz = member_position[2, m] - zi
                        r2 += dz * dz
                    if r2 < r2max:
                        j = member[m]
                        if j != i:
                            if found < width:
                                index[found, i] = j
                                distance[found, i] = math.sqrt(r2)
                            found += 1
    count[i] = min(found, width)
    if found > width:
        cuda.atomic.max(most, 0, found)


@cuda.jit(cache=True)
def neighbour_search(
    position, alive, lower, inverse, shape, rows, every, kind, radius, cell, count, cursor,
    sums, offsets, start, member, member_position, index, distance, list_count, most,
):  # fmt: skip
    """The neighbour lists in one cooperative launch, the grid meeting between the stages:
    each particle's cell (:func:`cell_of`); the cells' counts summed over tiles of ``BLOCK``
    cells (a tile by a block), the tiles' offsets (by one block) and each cell's start; the
    members scattered (:func:`scatter`) and sorted in particle order within each cell, and
    their coordinates copied in that order (:func:`sorted_positions`); then each row's search
    (:func:`search`). ``most[0]``: the widest row past the lists' width,
    0 when every row fits."""
    grid = cuda.cg.this_grid()
    shared = cuda.shared.array(BLOCK, dtype=int32)
    first = cuda.grid(1)
    stride = cuda.gridsize(1)
    n = position.shape[0]
    cells = count.shape[0]
    tiles = sums.shape[0]
    for c in range(first, cells, stride):
        count[c] = 0
        cursor[c] = 0
    if first == 0:
        most[0] = 0
    grid.sync()
    for i in range(first, n, stride):
        cell_of(i, position, alive, lower, inverse, shape, cell, count)
    grid.sync()
    for tile in range(cuda.blockIdx.x, tiles, cuda.gridDim.x):  # the same for a block's threads
        c = tile * BLOCK + cuda.threadIdx.x
        total = block_scan(shared, count[c] if c < cells else 0)
        if cuda.threadIdx.x == BLOCK - 1:
            sums[tile] = total
    grid.sync()
    if cuda.blockIdx.x == 0:
        tile_offsets(sums, offsets, shared)
    grid.sync()
    for tile in range(cuda.blockIdx.x, tiles, cuda.gridDim.x):
        c = tile * BLOCK + cuda.threadIdx.x
        inclusive = block_scan(shared, count[c] if c < cells else 0)
        if c < cells:
            start[c + 1] = offsets[tile] + inclusive
    if first == 0:
        start[0] = 0
    grid.sync()
    for i in range(first, n, stride):
        scatter(i, cell, start, cursor, member)
    grid.sync()
    for c in range(first, cells, stride):
        sort_cell(c, start, member)
    grid.sync()
    for m in range(first, n, stride):
        sorted_positions(m, start, member, position, member_position)
    grid.sync()
    for i in range(first, n, stride):
        search(
            i, position, rows, every, kind, cell, start, member, member_position, shape,
            radius, index, distance, list_count, most,
        )  # fmt: skip


# ------------------------------------------------------------------------ particle models


@cuda.jit(device=True)
def number_density(i, index, distance, count, re, out, within):
    """Eq. (F2), and the neighbours within r_e (neighbour-count surface)."""
    total = 0.0
    found = 0
    for m in range(count[i]):
        r = distance[m, i]
        if r < re:
            total += weight(r, re)
            found += 1
    out[i] = total
    within[i] = found


@cuda.jit(device=True)
def explicit_stage(
    i, position, velocity, kind, alive, index, distance, count, re, coefficient, gravity,
    external, has_external, density, dt, out_position, out_velocity,
):  # fmt: skip
    """Eq. (F5): u* and r* of live fluid particles; other particles copied."""
    dim = position.shape[1]
    for k in range(dim):
        out_velocity[i, k] = velocity[i, k]
        out_position[i, k] = position[i, k]
    if not (alive[i] and kind[i] == FLUID):
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


@cuda.jit(device=True)
def collision(
    i, position, velocity, kind, alive, index, count, reach, half, dt, out_position, out_velocity,
):  # fmt: skip
    """Eq. (F6), the Jacobi form of :func:`jellysim.fluid.kernels.collision`."""
    dim = position.shape[1]
    for k in range(dim):
        out_velocity[i, k] = velocity[i, k]
        out_position[i, k] = position[i, k]
    if not (alive[i] and kind[i] == FLUID):
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


@cuda.jit(device=True)
def classify(
    i, alive, kind, density_star, density_start, within, threshold, by_count, count_threshold,
    either, unknown, counts,
):  # fmt: skip
    """The unknowns of the PPE: live fluid and wall particles not on the free surface, Eq.
    (F7) or (F7b) (``unknown`` 1, else 0)."""
    solid = alive[i] and kind[i] != DUMMY
    surface = density_star[i] < threshold
    if by_count and within[i] < count_threshold:
        surface = True
    if either and density_start[i] < threshold:
        surface = True
    unknown[i] = 1 if (solid and not surface) else 0
    if solid and surface:
        cuda.atomic.add(counts, SURFACE, 1)


@cuda.jit(device=True)
def assemble(
    i, position, velocity, kind, alive, index, distance, count, unknown, re_lap, a_coefficient,
    shift, re_grad, div_coefficient, mixed, source_scale, mixed_scale, n0, density_star,
    density_start, pressure, coefficient, diagonal, inverse_diagonal, b, x, single,
):  # fmt: skip
    """Eq. (F8)-(F9): the PPE row of particle i (``coefficient[m, i]`` = a_ij for unknown
    neighbours, 0 else; ``diagonal``), its source ``b`` and the warm start ``x``; zeros for
    the particles that are no unknowns (diagonal, inverse_diagonal, b, x). ``coefficient``'s
    slots past a row's count, and its rows for the particles that are no unknowns (diagonal
    0), are left as they are: the CG and the coarse matrix read neither. With ``single``
    (fluid.matrix_precision, ``coefficient`` float32) the unknown neighbours' a_ij are
    rounded to single precision and the diagonal (double) sums them so rounded: the row's
    excess over them, its free-surface neighbours' a_ij and the shift, stays the double one."""
    if unknown[i] == 0:
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
        if kind[j] == DUMMY or not alive[j]:
            continue
        if r < re_lap:
            a = a_coefficient * weight(r, re_lap)
            if unknown[j] == 1:
                if single:
                    a = float64(float32(a))
                coefficient[m, i] = a
            total += a
        if mixed and r < re_grad:
            dot = 0.0
            for k in range(dim):
                dot += (velocity[j, k] - velocity[i, k]) * (position[j, k] - position[i, k])
            divergence += dot / (r * r) * weight(r, re_grad)
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


@cuda.jit(cache=True)
def coarse_flags(cell, diagonal, shape, k, coarse_shape, flags):
    """``flags[a]`` 1 for the aggregates that hold an unknown row (the same value written
    by every such row: the result does not depend on the order)."""
    i = cuda.grid(1)
    if i < cell.shape[0] and cell[i] >= 0 and diagonal[i] != 0.0:
        flags[coarse_block(cell[i], shape, k, coarse_shape)] = 1


@cuda.jit(cache=True)
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
    to_coarse, blocks, inverse, coarse_r, coarse_z, team, shared,
):  # fmt: skip
    """``z = D^-1 r + Z E^-1 Z^T r`` over the grid (``r`` complete on entry; each thread
    writes z on its own rows), in two grid barriers. An aggregate a team of ``team`` threads
    (BLOCK / team aggregates a block at a time): r summed over its members (each row of its
    k x k (x k) search cells along x one run of the search's sorted members; each lane a
    strided share, then the team's tree); then E^-1's row a team, the same way; then each
    unknown row's aggregate's value added to its Jacobi term. Fixed orders throughout,
    whatever the grid (``shared``: the block's BLOCK float64 scratch)."""
    grid = cuda.cg.this_grid()
    lane = cuda.threadIdx.x % team
    teams = BLOCK // team
    m = blocks.shape[0]
    # the same trip count for a block's threads: team_sum meets the block
    for first_team in range(cuda.blockIdx.x * teams, m, cuda.gridDim.x * teams):
        a = first_team + cuda.threadIdx.x // team
        total = 0.0
        if a < m:
            aggregate = blocks[a]
            bx = aggregate % coarse_shape[0]
            rest = aggregate // coarse_shape[0]
            by = rest % coarse_shape[1]
            bz = rest // coarse_shape[1]
            x0 = bx * k
            x1 = min(x0 + k, shape[0])
            for fz in range(bz * k, min(bz * k + k, shape[2])):
                for fy in range(by * k, min(by * k + k, shape[1])):
                    row = shape[0] * (fy + shape[1] * fz)
                    for s in range(start[row + x0] + lane, start[row + x1], team):
                        total += r[member[s]]
        total = team_sum(shared, total, team)
        if lane == 0 and a < m:
            coarse_r[a] = total
    grid.sync()
    for first_team in range(cuda.blockIdx.x * teams, m, cuda.gridDim.x * teams):
        a = first_team + cuda.threadIdx.x // team
        total = 0.0
        if a < m:
            for col in range(lane, m, team):
                total += inverse[a, col] * coarse_r[col]  # E^-1 symmetric: its row a
        total = team_sum(shared, total, team)
        if lane == 0 and a < m:
            coarse_z[a] = total
    grid.sync()
    for i in range(cuda.grid(1), r.shape[0], cuda.gridsize(1)):
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
        k += BLOCK
    return block_sum(shared, value)


@cuda.jit(cache=True)
def conjugate_gradient(
    index, count, coefficient, diagonal, inverse_diagonal, b, x, r, z, d, q, partial,
    tolerance2, max_iterations, out, cell, start, member, shape, k, coarse_shape,
    to_coarse, blocks, inverse, coarse_r, coarse_z, team,
):  # fmt: skip
    """Preconditioned CG for ``A x = b`` from the guess in ``x``, all iterations in one
    cooperative launch: each thread takes every gridsize-th row, and the grid meets at
    three barriers an iteration (the dot products' block sums are posted to one of two
    slots by turns, so that a slot is rewritten only after every block has read it).
    The preconditioner is Jacobi, or with aggregates (``blocks`` not empty) Jacobi plus
    the coarse correction of :func:`two_level`, three barriers more. Stops when ``r.r <=
    tolerance2 b.b`` or after ``max_iterations``; ``out`` = (iterations, r.r, b.b, 1 if some
    entry of x is not finite else 0). Every thread computes the same scalars, so all take
    the same branches."""
    grid = cuda.cg.this_grid()
    shared = cuda.shared.array(BLOCK, dtype=float64)
    first = cuda.grid(1)
    stride = cuda.gridsize(1)
    n = b.shape[0]
    a = 0.0
    c = 0.0
    e = 0.0
    coarse = blocks.shape[0] > 0
    if first == 0:
        out[3] = 0.0  # before the first barrier; set to 1 only after it
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
            to_coarse, blocks, inverse, coarse_r, coarse_z, team, shared,
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
                coarse_shape, to_coarse, blocks, inverse, coarse_r, coarse_z, team, shared,
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
    for i in range(first, n, stride):  # each thread's own rows of x, as it left them
        if not math.isfinite(x[i]):
            out[3] = 1.0
    if first == 0:
        out[0] = iterations
        out[1] = rr
        out[2] = bb


@cuda.jit(device=True)
def mark_wet(i, kind, alive, index, count, wet):
    """``wet`` 1 for live fluid particles and the walls in their lists (at r^k)."""
    if not (alive[i] and kind[i] == FLUID):
        return
    wet[i] = 1
    for m in range(count[i]):
        j = index[m, i]
        if kind[j] == WALL:
            wet[j] = 1


@cuda.jit(device=True)
def wet_rows(i, position, start, kind, alive, wet, margin, rows):
    """The rows of the list at r*, as :meth:`MPSSolver._wet`: the wet particles, or all
    live fluid and wall particles when some particle has moved more than ``margin``
    (``wet[n]``, set here by any thread that finds one, and read by the search)."""
    n = kind.shape[0]
    rows[i] = alive[i] and kind[i] != DUMMY and wet[i] == 1
    if alive[i]:
        r2 = 0.0
        for k in range(position.shape[1]):
            d = position[i, k] - start[i, k]
            r2 += d * d
        if r2 > margin * margin:
            wet[n] = 1


@cuda.jit(cache=True)
def fill(array, value):
    i = cuda.grid(1)
    if i < array.shape[0]:
        array[i] = value


@cuda.jit(device=True)
def store_pressure(i, unknown, x, pressure):
    pressure[i] = max(x[i], 0.0) if unknown[i] == 1 else 0.0


@cuda.jit(cache=True)
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
        if det < CORRECTION_MIN_DETERMINANT:
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
    if det < CORRECTION_MIN_DETERMINANT:
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


@cuda.jit(device=True)
def lowest_pressure(i, pressure, kind, alive, index, distance, count, re, lowest):
    """p_min,i of Eq. (F10c): the least pressure of i and its live fluid and wall neighbours
    within r_e (its own where it has no row)."""
    least = pressure[i]
    if alive[i]:
        for m in range(count[i]):
            j = index[m, i]
            if distance[m, i] < re and kind[j] != DUMMY and alive[j]:
                least = min(least, pressure[j])
    lowest[i] = least


@cuda.jit(device=True)
def correct(
    i, position, velocity, pressure, kind, alive, index, distance, count, re, re_lap,
    n0_gradient, coefficient, dt, corrected, conservative, lowest, repulse, unknown,
    out_position, out_velocity,
):  # fmt: skip
    """Eq. (F10), (F10a), (F10b) or (F10c) and the correction Eq. (F13)."""
    dim = position.shape[1]
    for k in range(dim):
        out_velocity[i, k] = velocity[i, k]
        out_position[i, k] = position[i, k]
    if not (alive[i] and kind[i] == FLUID):
        return
    gradient = cuda.local.array(3, dtype=float64)
    for k in range(3):
        gradient[k] = 0.0
    if conservative:
        for m in range(count[i]):
            j = index[m, i]
            r = distance[m, i]
            if r >= re or kind[j] == DUMMY or not alive[j]:
                continue
            excess = (pressure[i] + pressure[j]) - (lowest[i] + lowest[j])
            scale = excess / (r * r) * weight(r, re)
            for k in range(dim):
                gradient[k] += scale * (position[j, k] - position[i, k])
    else:
        least = pressure[i]
        for m in range(count[i]):
            j = index[m, i]
            if distance[m, i] < re and kind[j] != DUMMY:
                least = min(least, pressure[j])
        for m in range(count[i]):
            j = index[m, i]
            r = distance[m, i]
            if r >= re or kind[j] == DUMMY:
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
                if r >= re or kind[j] == DUMMY:
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
                if kind[j] == DUMMY or r >= re_lap or r == 0.0:
                    continue
                w = weight(r, re_lap) / r
                for k in range(dim):
                    normal[k] -= w * (position[j, k] - position[i, k])
                if r < re:
                    if kind[j] == FLUID:
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


@cuda.jit(device=True)
def escape(i, position, velocity, pressure, kind, alive, lower, upper, counts):
    """Live fluid particles outside the domain or no longer finite die; ``counts[DEAD]``
    counts them (an integer sum: the same whatever the order)."""
    if not (alive[i] and kind[i] == FLUID):
        return
    dying = False
    for k in range(position.shape[1]):
        x = position[i, k]
        u = velocity[i, k]
        if not (math.isfinite(x) and math.isfinite(u)) or x < lower[k] or x > upper[k]:
            dying = True
    if dying:
        alive[i] = False
        cuda.atomic.add(counts, DEAD, 1)
        pressure[i] = 0.0
        for k in range(position.shape[1]):
            velocity[i, k] = 0.0


@cuda.jit(device=True)
def extent_of(i, position, velocity, kind, alive, axis, out):
    """Particle i's share of :func:`extent`."""
    if not (alive[i] and kind[i] == FLUID):
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


@cuda.jit(cache=True)
def extent(position, velocity, kind, alive, axis, out):
    """out = (largest speed^2, largest and minus the least coordinate along ``axis``, live
    fluid count) over live fluid particles (maxima: the same whatever the order), from
    ``out`` = (0, -inf, -inf, 0)."""
    i = cuda.grid(1)
    if i < position.shape[0]:
        extent_of(i, position, velocity, kind, alive, axis, out)


# ---------------------------------------------------------------- a step's phases, fused
# Each phase of a step is one cooperative launch (its blocks all resident, the grid meeting
# at barriers between its stages), not a launch a stage: a launch costs tens of microseconds
# on the host, more than a stage's work on the GPU at 57,000 particles (docs/performance.md).
# Each stage is a device function above on every gridsize-th particle (the search's tile
# stages: every gridDim-th tile, a tile by a block).


@cuda.jit(cache=True)
def explicit_phase(
    position, velocity, kind, alive, index, distance, list_count, re_nd, mixed,
    start_density, within, re_lap, viscous, gravity, external, has_external, density, dt,
    reach, half, start_position, scratch_position, scratch_velocity, wet, margin, rows,
):  # fmt: skip
    """The step from the lists at r^k to the rows of the lists at r*: the wet particles
    (:func:`mark_wet`, from ``wet`` all 0), the number density at r^k where the source is
    mixed, r^k kept in ``start_position``, Eq. (F5) into the scratch arrays, the collisions
    back into the state, and the rows at r* (:func:`wet_rows`)."""
    grid = cuda.cg.this_grid()
    first = cuda.grid(1)
    stride = cuda.gridsize(1)
    n = position.shape[0]
    for i in range(first, n + 1, stride):
        wet[i] = 0
    grid.sync()
    for i in range(first, n, stride):
        mark_wet(i, kind, alive, index, list_count, wet)
        if mixed:
            number_density(i, index, distance, list_count, re_nd, start_density, within)
        for k in range(position.shape[1]):
            start_position[i, k] = position[i, k]
        explicit_stage(
            i, position, velocity, kind, alive, index, distance, list_count, re_lap, viscous,
            gravity, external, has_external, density, dt, scratch_position, scratch_velocity,
        )  # fmt: skip
    grid.sync()
    for i in range(first, n, stride):
        collision(
            i, scratch_position, scratch_velocity, kind, alive, index, list_count, reach, half,
            dt, position, velocity,
        )  # fmt: skip
        wet_rows(i, position, start_position, kind, alive, wet, margin, rows)  # its own row


@cuda.jit(cache=True)
def assembly_phase(
    position, velocity, kind, alive, index, distance, list_count, re_nd, density, within,
    start_density, threshold, by_count, count_threshold, either, unknown, counts, re_lap,
    a_coefficient, shift, re_grad, div_coefficient, mixed, source_scale, mixed_scale, n0,
    pressure, coefficient, diagonal, inverse_diagonal, b, x, single,
):  # fmt: skip
    """The Poisson system at r*: the number density (Eq. F2), the unknowns (:func:`classify`,
    the free-surface particles counted in ``counts[SURFACE]`` from 0) and each row
    (:func:`assemble`; ``single``: its entries rounded to single precision)."""
    grid = cuda.cg.this_grid()
    first = cuda.grid(1)
    stride = cuda.gridsize(1)
    n = position.shape[0]
    if first == 0:
        counts[SURFACE] = 0
    for i in range(first, n, stride):
        number_density(i, index, distance, list_count, re_nd, density, within)
    grid.sync()
    for i in range(first, n, stride):
        classify(
            i, alive, kind, density, start_density, within, threshold, by_count,
            count_threshold, either, unknown, counts,
        )  # fmt: skip
    grid.sync()
    for i in range(first, n, stride):
        assemble(
            i, position, velocity, kind, alive, index, distance, list_count, unknown, re_lap,
            a_coefficient, shift, re_grad, div_coefficient, mixed, source_scale, mixed_scale,
            n0, density, start_density, pressure, coefficient, diagonal, inverse_diagonal, b,
            x, single,
        )  # fmt: skip


@cuda.jit(cache=True)
def correction_phase(
    position, velocity, pressure, kind, alive, index, distance, list_count, unknown, x,
    re_grad, re_lap, n0_gradient, coefficient, dt, corrected, conservative, lowest, repulse,
    scratch_position, scratch_velocity, lower, upper, counts, axis, out_extent,
):  # fmt: skip
    """From the solve's ``x`` to the next state: the pressures (:func:`store_pressure`),
    p_min (Eq. F10c, when ``conservative``), the correction (Eq. F13) into the scratch arrays
    and from there into the state, the escaped particles dead (counted in ``counts[DEAD]``),
    and the new state's :func:`extent` into ``out_extent``, for the next step's dt."""
    grid = cuda.cg.this_grid()
    first = cuda.grid(1)
    stride = cuda.gridsize(1)
    n = position.shape[0]
    if first == 0:
        out_extent[0] = 0.0
        out_extent[1] = -math.inf
        out_extent[2] = -math.inf
        out_extent[3] = 0.0
    for i in range(first, n, stride):
        store_pressure(i, unknown, x, pressure)
    grid.sync()
    if conservative:
        for i in range(first, n, stride):
            lowest_pressure(i, pressure, kind, alive, index, distance, list_count, re_grad, lowest)
        grid.sync()
    for i in range(first, n, stride):
        correct(
            i, position, velocity, pressure, kind, alive, index, distance, list_count, re_grad,
            re_lap, n0_gradient, coefficient, dt, corrected, conservative, lowest, repulse,
            unknown, scratch_position, scratch_velocity,
        )  # fmt: skip
    grid.sync()
    for i in range(first, n, stride):
        for k in range(position.shape[1]):
            position[i, k] = scratch_position[i, k]
            velocity[i, k] = scratch_velocity[i, k]
        escape(i, position, velocity, pressure, kind, alive, lower, upper, counts)
        extent_of(i, position, velocity, kind, alive, axis, out_extent)


# every kernel and device function by name, as GPUSolver looks them up
KERNELS = {
    "weight": weight,
    "block_sum": block_sum,
    "cell_coordinate": cell_coordinate,
    "cell_of": cell_of,
    "block_scan": block_scan,
    "tile_offsets": tile_offsets,
    "scatter": scatter,
    "sort_cell": sort_cell,
    "sorted_positions": sorted_positions,
    "search": search,
    "neighbour_search": neighbour_search,
    "number_density": number_density,
    "explicit_stage": explicit_stage,
    "collision": collision,
    "classify": classify,
    "assemble": assemble,
    "coarse_block": coarse_block,
    "coarse_flags": coarse_flags,
    "coarse_matrix": coarse_matrix,
    "team_sum": team_sum,
    "two_level": two_level,
    "product": product,
    "post": post,
    "gathered": gathered,
    "conjugate_gradient": conjugate_gradient,
    "mark_wet": mark_wet,
    "wet_rows": wet_rows,
    "fill": fill,
    "store_pressure": store_pressure,
    "weighted_sums": weighted_sums,
    "solve_small": solve_small,
    "lowest_pressure": lowest_pressure,
    "correct": correct,
    "escape": escape,
    "extent": extent,
    "extent_of": extent_of,
    "explicit_phase": explicit_phase,
    "assembly_phase": assembly_phase,
    "correction_phase": correction_phase,
}
