"""Neighbour search of the MPS fluid: the cell list, Verlet-list filtering and their helpers.

Positions ``(N, D)`` float64 in m (D = 2 or 3), ``alive (N,)`` bool. Every parallel loop is a
gather: particle i (or a fixed chunk of rows) reads the cells around it and writes only its own
rows, so the lists are bitwise identical whatever the number of threads.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numba import njit, prange


class Neighbours(NamedTuple):
    """Neighbour list in CSR form: particle i's neighbours are ``indices[start[i]:start[i+1]]``
    (live particles within ``radius`` of it, itself excluded) at distances ``distance`` (m)."""

    start: np.ndarray  # (N + 1,) int64
    indices: np.ndarray  # (M,) int32 (a quarter less to write and read than int64)
    distance: np.ndarray  # (M,) float64
    radius: float  # m


# Cells of side radius / CELLS_PER_RADIUS: particle i scans the (2 CELLS_PER_RADIUS + 1)^D cells
# around its own, a volume of (2 + 1 / CELLS_PER_RADIUS)^D radius^D (27 radius^3 with cells of
# side radius, 15.6 with half that).
CELLS_PER_RADIUS = 2


@njit(cache=True)
def room(buffer: np.ndarray, size: int) -> np.ndarray:
    """``buffer`` if it holds ``size`` entries, else a new one a quarter larger than that.

    The large arrays of a step (neighbour lists, the PPE matrix) are written into buffers the
    solver keeps from step to step: a fresh array of tens of megabytes is mapped anew by the
    allocator each time, and touching its pages for the first time cost more than filling
    them (tank-3d at 54,000: 1.1 steps/s with fresh arrays, docs/performance.md)."""
    if buffer.shape[0] >= size:
        return buffer
    return np.empty(size + size // 4, dtype=buffer.dtype)


class _Grid(NamedTuple):
    """The cell list of :func:`neighbour_list`, always three axes (a 2-D grid has one cell
    along z and zero z coordinates, so that the 2-D search is the 3-D one with its loops over z
    cut to one cell and distances bit for bit the same). Cells are numbered with x fastest;
    members of a cell are in particle order, and the cells along x are one run of members."""

    cell: np.ndarray  # (N, 3) int64, the cell coordinates of each live particle
    shape: np.ndarray  # (3,) int64
    stride: np.ndarray  # (3,) int64
    start: np.ndarray  # (cells + 1,) int64, members of cell c are start[c]:start[c + 1]
    member: np.ndarray  # (M,) int64, particle indices in cell order
    member_position: np.ndarray  # (3, M) float64, their coordinates, one contiguous run per axis
    position: np.ndarray  # (3, N) float64, every particle's coordinates, per axis


@njit(cache=True)
def _grid(position: np.ndarray, alive: np.ndarray, radius: float) -> _Grid:
    """Cells of side ``radius / CELLS_PER_RADIUS`` over the live particles' bounding box, filled
    by a stable counting sort that also copies the members' coordinates in cell order."""
    n, dim = position.shape
    coordinates = np.zeros((3, n))
    for i in range(n):
        for k in range(dim):
            coordinates[k, i] = position[i, k]
    lower = np.zeros(3)
    upper = np.zeros(3)
    lower[:dim] = np.inf
    upper[:dim] = -np.inf
    for i in range(n):
        if alive[i]:
            for k in range(dim):
                lower[k] = min(lower[k], coordinates[k, i])
                upper[k] = max(upper[k], coordinates[k, i])
    inverse = CELLS_PER_RADIUS / radius
    shape = np.ones(3, dtype=np.int64)
    for k in range(dim):
        if upper[k] >= lower[k]:
            shape[k] = int((upper[k] - lower[k]) * inverse) + 1
    stride = np.array([1, shape[0], shape[0] * shape[1]], dtype=np.int64)
    n_cells = stride[2] * shape[2]
    cell_of = np.full(n, -1, dtype=np.int64)
    cell = np.zeros((n, 3), dtype=np.int64)
    start = np.zeros(n_cells + 1, dtype=np.int64)
    for i in range(n):
        if alive[i]:
            c = 0
            for k in range(dim):
                q = min(int((coordinates[k, i] - lower[k]) * inverse), shape[k] - 1)
                cell[i, k] = q
                c += q * stride[k]
            cell_of[i] = c
            start[c + 1] += 1
    for c in range(n_cells):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    member = np.empty(start[n_cells], dtype=np.int64)
    member_position = np.zeros((3, start[n_cells]))
    for i in range(n):
        if cell_of[i] >= 0:
            m = fill[cell_of[i]]
            member[m] = i
            for k in range(3):
                member_position[k, m] = coordinates[k, i]
            fill[cell_of[i]] += 1
    return _Grid(cell, shape, stride, start, member, member_position, coordinates)


@njit(cache=True)
def _scan_cells(
    i: int,
    cell: np.ndarray,
    shape: np.ndarray,
    stride: np.ndarray,
    start: np.ndarray,
    member: np.ndarray,
    member_position: np.ndarray,
    position: np.ndarray,
    radius2: float,
    index: np.ndarray,
    distance: np.ndarray,
    slot: int,
    near_radius: float,
) -> tuple[int, int]:
    """Particle i's neighbours closer than sqrt(radius2) in the cells around its own, in
    cell order then member order, written from ``slot`` on into ``index`` and ``distance``, as
    far as those reach. Returns how many there are (all of them, also those that did not fit)
    and how many of them are closer than ``near_radius`` (their stored distance, as
    :func:`near_neighbours` tests it).

    The loops are written out for three axes with the coordinates in separate arrays: the
    compiler then keeps the candidate loop free of inner loops (about twice as fast as a loop
    over D). The arguments are the fields of :class:`_Grid` (passed one by one: a tuple built
    inside a parallel function cannot be handed to its parallel loops)."""
    cx = cell[i, 0]
    cy = cell[i, 1]
    cz = cell[i, 2]
    first_x = max(cx - CELLS_PER_RADIUS, 0)
    last_x = min(cx + CELLS_PER_RADIUS, shape[0] - 1)
    xi = position[0, i]
    yi = position[1, i]
    zi = position[2, i]
    mx = member_position[0]
    my = member_position[1]
    mz = member_position[2]
    found = 0
    near = 0
    for qz in range(max(cz - CELLS_PER_RADIUS, 0), min(cz + CELLS_PER_RADIUS, shape[2] - 1) + 1):
        for qy in range(
            max(cy - CELLS_PER_RADIUS, 0), min(cy + CELLS_PER_RADIUS, shape[1] - 1) + 1
        ):
            c = qy * stride[1] + qz * stride[2]
            first = start[c + first_x]
            last = start[c + last_x + 1]
            for m in range(first, last):
                dx = mx[m] - xi
                dy = my[m] - yi
                dz = mz[m] - zi
                r2 = dx * dx + dy * dy + dz * dz
                if r2 < radius2:
                    j = member[m]
                    if j != i:
                        r = math.sqrt(r2)
                        if slot + found < index.shape[0]:
                            index[slot + found] = j
                            distance[slot + found] = r
                        found += 1
                        near += r < near_radius
    return found, near


@njit(cache=True)
def _cut_row(
    index: np.ndarray,
    distance: np.ndarray,
    first: int,
    last: int,
    radius: float,
    near_index: np.ndarray,
    near_distance: np.ndarray,
    slot: int,
    end: int,
) -> None:
    """The entries ``first:last`` of a list closer than ``radius`` (m), in their order, into
    ``near_index`` and ``near_distance`` from ``slot`` to ``end`` (their count). Every entry is
    written at the next free slot, which moves on only for a near one: no branch on the
    distance, which the processor would mispredict wherever the particles are off their
    lattice (the test of the slot fails only once the row's last near entry is in)."""
    for m in range(first, last):
        r = distance[m]
        if slot < end:
            near_index[slot] = index[m]
            near_distance[slot] = r
        slot += r < radius


# The one-pass search (:func:`search_neighbours`) fills the rows in chunks of SEARCH_CHUNK rows,
# each chunk's rows one after another in its own part of a scratch buffer, and a wave of chunks
# at a time: the wave's rows are counted as they are filled, then copied to their place in the
# list. A chunk that outgrows its part is searched again straight into the list. A wave holds
# WAVE_CHUNKS_PER_THREAD chunks for each thread, at least WAVE_CHUNKS and at most
# WAVE_CHUNKS_MOST (:func:`wave_chunks`), but the first, which learns how long the rows are,
# WAVE_CHUNKS: each thread's part of the scratch stays the size that fits its cache (about 2 MB
# in 3-D), and the waves, each of two parallel loops, get fewer as the threads get more; each
# scratch array stays within about 32 MB in 3-D, which glibc serves from its heap.
SEARCH_CHUNK = 32
WAVE_CHUNKS = 64
WAVE_CHUNKS_PER_THREAD = 32
WAVE_CHUNKS_MOST = 512


def wave_chunks() -> int:
    """The chunks of a wave of the search on the threads Numba uses now: 64 on 1 and 2 threads,
    512 from 16 on (the searches' ``wave_size``)."""
    wanted = WAVE_CHUNKS_PER_THREAD * numba.get_num_threads()
    return min(max(WAVE_CHUNKS, wanted), WAVE_CHUNKS_MOST)


# Entries a row the first wave's scratch holds; later waves' hold the widest chunk's mean so far,
# a quarter more (the list is the same whatever these are: they only decide which path it takes).
FIRST_ROW_ROOM = 64


@njit(cache=True)
def _keep_growing(buffer: np.ndarray, size: int, keep: int, estimate: int) -> np.ndarray:
    """``buffer`` if it holds ``size`` entries, else a new one of ``max(size, estimate)`` and a
    quarter more with ``buffer``'s first ``keep`` entries."""
    if buffer.shape[0] >= size:
        return buffer
    grown = np.empty(max(size, estimate) * 5 // 4, dtype=buffer.dtype)
    grown[:keep] = buffer[:keep]
    return grown


@njit(cache=True, parallel=True)
def search_in_waves(
    position: np.ndarray,
    alive: np.ndarray,
    rows: np.ndarray,
    radius: float,
    index: np.ndarray,
    distance: np.ndarray,
    row_room: int,
    near_radius: float,
    near_index: np.ndarray,
    near_distance: np.ndarray,
    wave_size: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`search_with_near` with the first wave's scratch ``row_room`` entries a row and
    ``wave_size`` chunks a wave (a test's handles on the paths the search can take; the lists
    are the same whatever they are). With ``near_radius`` 0 the near list is empty."""
    n = position.shape[0]
    cell, shape, stride, start, member, member_position, coordinates = _grid(
        position, alive, radius
    )
    radius2 = radius * radius
    # The rows to fill, compacted: the parallel loops split their iterations evenly between
    # the threads, and rows are not spread evenly over the particles (water first, then the
    # tank's walls mixed with its row-less dummies).
    active = np.flatnonzero(alive & rows)
    n_active = active.shape[0]
    found = np.zeros(n_active, dtype=np.int64)  # each active row's length
    near = np.zeros(n_active, dtype=np.int64)  # and its near entries
    offset = np.zeros(n_active + 1, dtype=np.int64)  # where it starts in the list
    near_offset = np.zeros(n_active + 1, dtype=np.int64)  # and in the near list
    chunks = (n_active + SEARCH_CHUNK - 1) // SEARCH_CHUNK
    wave_size = max(min(wave_size, chunks), 1)
    used = np.zeros(wave_size, dtype=np.int64)  # entries of a chunk's rows, -1 if outgrown
    room_row = max(row_room, 1)
    # The first wave, which learns the rows' room (a chunk that outgrows its part is searched
    # twice), is never wider than WAVE_CHUNKS; the later ones are wave_size wide.
    wave = min(wave_size, WAVE_CHUNKS, chunks)
    scratch_index = np.empty(wave * SEARCH_CHUNK * room_row, dtype=np.int32)
    scratch_distance = np.empty(wave * SEARCH_CHUNK * room_row)
    first_chunk = 0
    while first_chunk < chunks:
        part = SEARCH_CHUNK * room_row  # a chunk's part of the scratch
        for w in prange(wave):  # fill each chunk's rows into its part, counting them
            base = w * part
            chunk_index = scratch_index[base : base + part]
            chunk_distance = scratch_distance[base : base + part]
            first = (first_chunk + w) * SEARCH_CHUNK
            filled = 0
            for a in range(first, min(first + SEARCH_CHUNK, n_active)):
                found[a], near[a] = _scan_cells(
                    active[a], cell, shape, stride, start, member, member_position,
                    coordinates, radius2, chunk_index, chunk_distance, filled, near_radius,
                )  # fmt: skip
                filled += found[a]
            used[w] = filled if filled <= part else -1
        first_row = first_chunk * SEARCH_CHUNK
        last_row = min((first_chunk + wave) * SEARCH_CHUNK, n_active)
        widest = 0
        for a in range(first_row, last_row):
            offset[a + 1] = offset[a] + found[a]
            near_offset[a + 1] = near_offset[a] + near[a]
        for w in range(wave):
            first = (first_chunk + w) * SEARCH_CHUNK
            last = min(first + SEARCH_CHUNK, n_active)
            widest = max(widest, offset[last] - offset[first])
        size = int(offset[last_row])
        estimate = size * n_active // max(last_row, 1) + 1  # the whole list, by the rows so far
        index = _keep_growing(index, size, int(offset[first_row]), estimate)
        distance = _keep_growing(distance, size, int(offset[first_row]), estimate)
        size = int(near_offset[last_row])
        estimate = size * n_active // max(last_row, 1) + 1
        near_index = _keep_growing(near_index, size, int(near_offset[first_row]), estimate)
        near_distance = _keep_growing(near_distance, size, int(near_offset[first_row]), estimate)
        for w in prange(wave):  # each chunk's rows to their place in the lists
            first = (first_chunk + w) * SEARCH_CHUNK
            last = min(first + SEARCH_CHUNK, n_active)
            target = offset[first]
            if used[w] >= 0:
                taken = w * part
                for t in range(used[w]):
                    index[target + t] = scratch_index[taken + t]
                    distance[target + t] = scratch_distance[taken + t]
            else:  # outgrown: the chunk's rows searched again, straight into the list
                for a in range(first, last):
                    _scan_cells(
                        active[a], cell, shape, stride, start, member, member_position,
                        coordinates, radius2, index, distance, offset[a], near_radius,
                    )  # fmt: skip
            if near_offset[last] > near_offset[first]:
                # the near entries of each row, from the chunk's rows just copied (in cache)
                for a in range(first, last):
                    _cut_row(
                        index, distance, offset[a], offset[a + 1], near_radius, near_index,
                        near_distance, near_offset[a], near_offset[a + 1],
                    )  # fmt: skip
        first_chunk += wave
        wave = min(wave_size, chunks - first_chunk)
        room_row = max(room_row, (widest * 5 // 4 + SEARCH_CHUNK - 1) // SEARCH_CHUNK)
        if wave * SEARCH_CHUNK * room_row > scratch_index.shape[0]:
            scratch_index = np.empty(wave * SEARCH_CHUNK * room_row, dtype=np.int32)
            scratch_distance = np.empty(wave * SEARCH_CHUNK * room_row)
    row_count = np.zeros(n + 1, dtype=np.int64)
    near_count = np.zeros(n + 1, dtype=np.int64)
    for a in range(n_active):
        row_count[active[a] + 1] = found[a]
        near_count[active[a] + 1] = near[a]
    for i in range(n):
        row_count[i + 1] += row_count[i]
        near_count[i + 1] += near_count[i]
    return row_count, index, distance, near_count, near_index, near_distance


@njit(cache=True)
def search_neighbours(
    position: np.ndarray,
    alive: np.ndarray,
    rows: np.ndarray,
    radius: float,
    index: np.ndarray,
    distance: np.ndarray,
    wave_size: int = WAVE_CHUNKS,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cell-list search: for every live particle i with ``rows[i]`` ((N,) bool), all live
    particles closer than ``radius`` (m); other rows are empty (such particles still appear as
    neighbours of others).

    Cells of side ``radius / CELLS_PER_RADIUS`` (:func:`_grid`); particle i scans the cells
    within ``CELLS_PER_RADIUS`` of its own along each axis, once: the rows are filled and
    counted in chunks (:data:`SEARCH_CHUNK`), a wave of ``wave_size`` chunks at a time (the
    solver passes :func:`wave_chunks`), then copied to their place (a count pass before the
    fill took half the search, docs/performance.md). Returns the
    arrays of :class:`Neighbours` ``(start, indices, distance)``; within a row the order is fixed
    (cell order, then particle index). ``indices`` and ``distance`` are the buffers ``index``
    ((K,) int32) and ``distance`` ((K,) float64) when they hold the list, else new ones, and run
    past the list's end ``start[N]``.
    """
    start, index, distance, _, _, _ = search_in_waves(
        position, alive, rows, radius, index, distance, FIRST_ROW_ROOM, 0.0,
        np.empty(0, dtype=np.int32), np.empty(0), wave_size,
    )  # fmt: skip
    return start, index, distance


@njit(cache=True)
def search_with_near(
    position: np.ndarray,
    alive: np.ndarray,
    rows: np.ndarray,
    radius: float,
    index: np.ndarray,
    distance: np.ndarray,
    near_radius: float,
    near_index: np.ndarray,
    near_distance: np.ndarray,
    wave_size: int = WAVE_CHUNKS,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`search_neighbours`, and the same list cut to ``near_radius`` (m) as
    :func:`near_neighbours` cuts it, taken as the rows are copied to their place (no second
    pass over the list): the arrays of both, the near list's in the buffers ``near_index`` and
    ``near_distance`` (or new ones)."""
    return search_in_waves(
        position, alive, rows, radius, index, distance, FIRST_ROW_ROOM, near_radius,
        near_index, near_distance, wave_size,
    )  # fmt: skip


@njit(cache=True)
def neighbour_list(
    position: np.ndarray, alive: np.ndarray, rows: np.ndarray, radius: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`search_neighbours` into arrays of the list's own length."""
    start, index, distance = search_neighbours(
        position, alive, rows, radius, np.empty(0, dtype=np.int32), np.empty(0)
    )
    return start, index[: start[-1]].copy(), distance[: start[-1]].copy()


@njit(cache=True, parallel=True)
def filter_with_near(
    candidates: Neighbours,
    position: np.ndarray,
    alive: np.ndarray,
    rows: np.ndarray,
    radius: float,
    index: np.ndarray,
    distance: np.ndarray,
    near_radius: float,
    near_index: np.ndarray,
    near_distance: np.ndarray,
    scratch: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`filter_neighbours`' list and, in the same passes, its entries closer than
    ``near_radius`` (m; 0 for none): the list :func:`near_neighbours` would cut from it. Returns
    the arrays of both lists, in the buffers ``index``, ``distance``, ``near_index`` and
    ``near_distance`` (or new ones), and the buffer ``scratch`` (or a new one), which holds a
    float for every candidate.

    Neither pass branches on a distance, which the processor would mispredict wherever the
    particles are off their lattice: the first measures every candidate of a row into
    ``scratch`` (its distance, or infinity for one that is not kept) and counts the row's
    entries of both lists by adding comparisons; the second writes every candidate at the next
    free slot of each list, which moves on only for an entry that list keeps. At moon-jelly's
    size off the lattice, 71 ms on 2 threads where the filter of two passes with a branch and the
    near cut after it took 125 (docs/performance.md, "A Verlet list without branches")."""
    n, dim = position.shape
    coordinates = np.zeros((3, n))
    for i in prange(n):
        for k in range(dim):
            coordinates[k, i] = position[i, k]
    x = coordinates[0]
    y = coordinates[1]
    z = coordinates[2]
    active = np.flatnonzero(alive & rows)
    radius2 = radius * radius
    scratch = room(scratch, candidates.indices.shape[0])
    start = np.zeros(n + 1, dtype=np.int64)
    near_start = np.zeros(n + 1, dtype=np.int64)
    for a in prange(active.shape[0]):  # first pass: measure and count each row
        i = active[a]
        xi = x[i]
        yi = y[i]
        zi = z[i]
        found = 0
        near = 0
        for m in range(candidates.start[i], candidates.start[i + 1]):
            j = candidates.indices[m]
            dx = x[j] - xi
            dy = y[j] - yi
            dz = z[j] - zi
            r2 = dx * dx + dy * dy + dz * dz
            keep = (r2 < radius2) & alive[j]
            r = math.sqrt(r2) if keep else math.inf
            scratch[m] = r
            found += keep
            near += r < near_radius
        start[i + 1] = found
        near_start[i + 1] = near
    for i in range(n):
        start[i + 1] += start[i]
        near_start[i + 1] += near_start[i]
    index = room(index, int(start[n]))
    distance = room(distance, int(start[n]))
    near_index = room(near_index, int(near_start[n]))
    near_distance = room(near_distance, int(near_start[n]))
    for a in prange(active.shape[0]):  # second pass: fill each row of both lists
        i = active[a]
        first, last = candidates.start[i], candidates.start[i + 1]
        _cut_row(
            candidates.indices, scratch, first, last, math.inf, index, distance, start[i],
            start[i + 1],
        )  # fmt: skip
        _cut_row(
            candidates.indices, scratch, first, last, near_radius, near_index, near_distance,
            near_start[i], near_start[i + 1],
        )  # fmt: skip
    return start, index, distance, near_start, near_index, near_distance, scratch


@njit(cache=True)
def filter_neighbours(
    candidates: Neighbours,
    position: np.ndarray,
    alive: np.ndarray,
    rows: np.ndarray,
    radius: float,
    index: np.ndarray,
    distance: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The neighbour list within ``radius`` (m) at ``position``, for the live particles with
    ``rows[i]``, taken from a list of ``candidates`` built at other positions with a larger
    radius (a Verlet list: it holds every pair now closer than ``radius`` while no particle
    has moved more than half the difference of the radii since it was built). Within a row,
    the candidates' order. Returns the arrays of :class:`Neighbours` in the buffers ``index``
    and ``distance`` (or new ones), like :func:`search_neighbours`
    (:func:`filter_with_near` without its near list, its scratch a new array)."""
    lists = filter_with_near(
        candidates, position, alive, rows, radius, index, distance, 0.0,
        np.empty(0, dtype=np.int32), np.empty(0), np.empty(0),
    )  # fmt: skip
    return lists[0], lists[1], lists[2]


@njit(cache=True, parallel=True)
def near_neighbours(
    neighbours: Neighbours, radius: float, index: np.ndarray, distance: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The entries of ``neighbours`` closer than ``radius`` (m), each row's in the order of
    ``neighbours``: a sum over them is the same sum, bit for bit, as one over the whole row that
    skips the entries at ``radius`` or beyond. Returns the arrays of :class:`Neighbours` in the
    buffers ``index`` and ``distance`` (or new ones), like :func:`search_neighbours`.

    The kernels whose radius is the number-density and gradient radius (2.1 l0) read this
    list instead of the whole one, drawn at the Laplacian radius (3.1 l0 in 3-D, 4 l0 in 2-D):
    a third of the entries, and no test on each that the processor mispredicts wherever the
    particles are off their lattice (docs/performance.md, "Lists at the near radius"). Both
    passes are free of such branches: rows are counted by adding the comparisons, and filled by
    writing every entry at the next free slot, which moves on only for a near one."""
    n = neighbours.start.shape[0] - 1
    start = np.zeros(n + 1, dtype=np.int64)
    for i in prange(n):
        count = 0
        for m in range(neighbours.start[i], neighbours.start[i + 1]):
            count += neighbours.distance[m] < radius
        start[i + 1] = count
    for i in range(n):
        start[i + 1] += start[i]
    index = room(index, int(start[n]))
    distance = room(distance, int(start[n]))
    for i in prange(n):
        _cut_row(
            neighbours.indices, neighbours.distance, neighbours.start[i],
            neighbours.start[i + 1], radius, index, distance, start[i], start[i + 1],
        )  # fmt: skip
    return start, index, distance


@njit(cache=True, parallel=True)
def listed(neighbours: Neighbours, rows: np.ndarray) -> np.ndarray:
    """(N,) bool: the particles that appear in the rows ``rows`` ((R,) int64) of
    ``neighbours``. (Threads may store True into the same entry: the outcome is the same.)"""
    out = np.zeros(neighbours.start.shape[0] - 1, dtype=np.bool_)
    for a in prange(rows.shape[0]):
        i = rows[a]
        for m in range(neighbours.start[i], neighbours.start[i + 1]):
            out[neighbours.indices[m]] = True
    return out


@njit(cache=True, parallel=True)
def largest_displacement(position: np.ndarray, reference: np.ndarray, alive: np.ndarray) -> float:
    """The largest distance (m) of a live particle from its ``reference`` position."""
    n, dim = position.shape
    largest = np.zeros(n)
    for i in prange(n):
        if alive[i]:
            r2 = 0.0
            for k in range(dim):
                d = position[i, k] - reference[i, k]
                r2 += d * d
            largest[i] = r2
    return math.sqrt(largest.max()) if n else 0.0
