"""MPS kernels against closed forms and slow oracles: weights and lattice constants as data,
cell list against brute force, momentum of the explicit stage and the collision model."""

from __future__ import annotations

import itertools
import math
import os
import subprocess
import sys

import numba
import numpy as np
import pytest

from jellysim.fluid import kernels, neighbours
from jellysim.fluid.geometry import DUMMY, FLUID, WALL, filled_height, tank, water_block
from jellysim.fluid.mps import MPSParameters, MPSSolver, lattice_reference

# Lattice shells (squared distance in l0^2, number of lattice points), counted by hand.
SHELLS_2D_R21 = [(1, 4), (2, 4), (4, 4)]  # 12 points; sqrt(5) = 2.236 lies outside 2.1
SHELLS_2D_R40 = [(1, 4), (2, 4), (4, 4), (5, 8), (8, 4), (9, 4), (10, 8), (13, 8)]  # 44
SHELLS_3D_R21 = [(1, 6), (2, 12), (3, 8), (4, 6)]  # 32
SHELLS_3D_R31 = [(1, 6), (2, 12), (3, 8), (4, 6), (5, 24), (6, 24), (8, 12), (9, 30)]  # 122
# Hexagonal lattice: |m_1 + m_2 e^(i pi/3)|^2 = m_1^2 + m_1 m_2 + m_2^2 (Loeschian numbers)
SHELLS_HEX_R21 = [(1, 6), (3, 6), (4, 6)]  # 18; sqrt(7) = 2.65 lies outside 2.1
SHELLS_HEX_R31 = [(1, 6), (3, 6), (4, 6), (7, 12), (9, 6)]  # 36
SHELLS_HEX_R40 = [(1, 6), (3, 6), (4, 6), (7, 12), (9, 6), (12, 6), (13, 12)]  # 54; 16 outside
# Face-centred cubic lattice, nearest neighbours at l0: its points are the integer vectors of
# even sum scaled by l0 / sqrt(2), so r^2 = (a^2 + b^2 + c^2) / 2 l0^2; the coordination shells
# r^2 = 1 ... 9 hold 12, 6, 24, 12, 24, 8, 48, 6 and 36 points.
SHELLS_FCC_R21 = [(1, 12), (2, 6), (3, 24), (4, 12)]  # 54; sqrt(5) = 2.236 lies outside 2.1
SHELLS_FCC_R31 = SHELLS_FCC_R21 + [(5, 24), (6, 8), (7, 48), (8, 6), (9, 36)]  # 176


def by_hand(shells: list[tuple[int, int]], re: float) -> tuple[float, float, int]:
    n0 = sum(count * (re / math.sqrt(r2) - 1.0) for r2, count in shells)
    moment = sum(count * (re / math.sqrt(r2) - 1.0) * r2 for r2, count in shells)
    return n0, moment / n0, sum(count for _, count in shells)


def test_weight_values() -> None:
    re = 2.1
    assert kernels.weight(1.0, re) == pytest.approx(1.1)
    assert kernels.weight(math.sqrt(2.0), re) == pytest.approx(0.48492424049175)
    assert kernels.weight(2.0, re) == pytest.approx(0.05)
    assert kernels.weight(2.1, re) == 0.0
    assert kernels.weight(3.0, re) == 0.0


@pytest.mark.parametrize(
    ("dim", "re", "shells", "n0_literal"),
    [
        (2, 2.1, SHELLS_2D_R21, 6.539696961967),
        (2, 4.0, SHELLS_2D_R40, None),
        (3, 2.1, SHELLS_3D_R21, None),
        (3, 3.1, SHELLS_3D_R31, None),
    ],
)
def test_lattice_constants_against_hand_counts(dim, re, shells, n0_literal) -> None:
    l0 = 0.01
    n0, lam, count = by_hand(shells, re)
    ref = lattice_reference(dim, l0, re)
    assert ref.count == count
    assert ref.n0 == pytest.approx(n0, rel=1e-12)
    assert ref.lambda_ == pytest.approx(lam * l0**2, rel=1e-12)
    if n0_literal is not None:
        assert ref.n0 == pytest.approx(n0_literal, rel=1e-12)


@pytest.mark.parametrize(
    ("re", "shells"), [(2.1, SHELLS_HEX_R21), (3.1, SHELLS_HEX_R31), (4.0, SHELLS_HEX_R40)]
)
def test_hexagonal_lattice_constants_against_hand_counts(re, shells) -> None:
    l0 = 0.005
    n0, lam, count = by_hand(shells, re)
    ref = lattice_reference(2, l0, re, "hexagonal")
    assert ref.count == count
    assert ref.n0 == pytest.approx(n0, rel=1e-12)
    assert ref.lambda_ == pytest.approx(lam * l0**2, rel=1e-12)


@pytest.mark.parametrize(("re", "shells"), [(2.1, SHELLS_FCC_R21), (3.1, SHELLS_FCC_R31)])
def test_fcc_lattice_constants_against_hand_counts(re, shells) -> None:
    """lattice_reference builds the fcc lattice from its (111) layers (the basis of
    :mod:`jellysim.fluid.geometry`); the hand count uses the cubic description."""
    l0 = 0.005
    n0, lam, count = by_hand(shells, re)
    ref = lattice_reference(3, l0, re, "fcc")
    assert ref.count == count
    assert ref.n0 == pytest.approx(n0, rel=1e-12)
    assert ref.lambda_ == pytest.approx(lam * l0**2, rel=1e-12)
    # 12 (re - 1) + 6 (re/sqrt(2) - 1) + 24 (re/sqrt(3) - 1) + 12 (re/2 - 1) at r_e = 2.1 l0
    if re == 2.1:
        assert ref.n0 == pytest.approx(21.807999010107643, rel=1e-12)


def test_hexagonal_n0_literal() -> None:
    # 6 (re/1 - 1) + 6 (re/sqrt(3) - 1) + 6 (re/2 - 1) at r_e = 2.1 l0
    assert lattice_reference(2, 0.005, 2.1, "hexagonal").n0 == pytest.approx(8.174613391789288)


def least_stiffness(lattice: str, re: float) -> float:
    """The least eigenvalue (in K / l0^2) of the dynamical matrix of the minimum-pressure
    gradient's pair repulsion F = K w(r) / r on a 2-D lattice, over a grid of wave vectors
    (docs/theory/fluid.md, "The lattice"): negative, the lattice is unstable."""
    reach = int(math.ceil(2 * re)) + 1
    m1, m2 = np.meshgrid(np.arange(-reach, reach + 1), np.arange(-reach, reach + 1))
    m1, m2 = m1.ravel().astype(float), m2.ravel().astype(float)
    if lattice == "hexagonal":
        points = np.column_stack([m1 + 0.5 * m2, math.sqrt(3.0) / 2.0 * m2])
    else:
        points = np.column_stack([m1, m2])
    r = np.sqrt((points**2).sum(axis=1))
    points, r = points[(r > 0) & (r < re)], r[(r > 0) & (r < re)]
    unit = points / r[:, None]
    force = (re / r - 1.0) / r
    slope = -2.0 * re / r**3 + 1.0 / r**2
    outer = unit[:, :, None] * unit[:, None, :]
    pair = -slope[:, None, None] * outer - (force / r)[:, None, None] * (np.eye(2) - outer)
    k = np.linspace(-2 * np.pi, 2 * np.pi, 41)
    waves = np.stack(np.meshgrid(k, k), axis=-1).reshape(-1, 2)
    weights = 1.0 - np.cos(waves @ points.T)  # (K, P)
    matrices = np.einsum("kp,pab->kab", weights, pair)
    return float(np.linalg.eigvalsh(matrices)[:, 0].min())


def test_lattice_stability_of_the_repulsion() -> None:
    """The square lattice held by the minimum-pressure gradient's repulsion is unstable to
    columns sliding past each other (least eigenvalue -1.43 K/l0^2 at r_e = 2.1 l0, at
    k = (pi/l0, 0)); the hexagonal lattice is stable at every radius (docs/theory/fluid.md)."""
    assert least_stiffness("square", 2.1) == pytest.approx(-1.4302, abs=1e-3)
    assert least_stiffness("square", 2.5) == pytest.approx(-0.920, abs=2e-3)
    assert least_stiffness("square", 3.1) == pytest.approx(-1.885, abs=2e-3)
    for re in (1.5, 2.1, 2.5, 3.1, 4.0):
        assert least_stiffness("hexagonal", re) > -1e-9


def least_stiffness_3d(lattice: str, re: float, samples: int = 17) -> float:
    """:func:`least_stiffness` on the cubic ("square") or face-centred cubic lattice in 3-D,
    over a grid of wave vectors with ``samples`` points per axis in [-2 pi, 2 pi] / l0."""
    reach = int(math.ceil(2 * re)) + 1
    axis = np.arange(-reach, reach + 1)
    m = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3).astype(float)
    if lattice == "fcc":
        m1, m2, m3 = m.T
        m = np.column_stack(
            [
                m1 + 0.5 * (m2 + m3),
                math.sqrt(3.0) / 2.0 * (m2 + m3 / 3.0),
                math.sqrt(2.0 / 3.0) * m3,
            ]
        )
    r = np.sqrt((m**2).sum(axis=1))
    points, r = m[(r > 0) & (r < re)], r[(r > 0) & (r < re)]
    unit = points / r[:, None]
    force = (re / r - 1.0) / r
    slope = -2.0 * re / r**3 + 1.0 / r**2
    outer = unit[:, :, None] * unit[:, None, :]
    pair = -slope[:, None, None] * outer - (force / r)[:, None, None] * (np.eye(3) - outer)
    k = np.linspace(-2 * np.pi, 2 * np.pi, samples)
    waves = np.stack(np.meshgrid(k, k, k, indexing="ij"), axis=-1).reshape(-1, 3)
    matrices = np.einsum("kp,pab->kab", 1.0 - np.cos(waves @ points.T), pair)
    return float(np.linalg.eigvalsh(matrices)[:, 0].min())


def test_lattice_stability_of_the_repulsion_in_3d() -> None:
    """In 3-D the cubic lattice is as unstable as the square one (least eigenvalue -2.86 K/l0^2
    at r_e = 2.1 l0). The face-centred cubic lattice is stable from r_e = 2.3 l0 on, but only
    nearly so at the gradient's 2.1 l0 (-0.19 on this grid of wave vectors, fifteen times less
    than the cubic lattice): its still water creeps, slowly (docs/theory/fluid.md)."""
    assert least_stiffness_3d("square", 2.1) == pytest.approx(-2.8603, abs=1e-3)
    cubic = least_stiffness_3d("square", 2.1)
    assert 0.1 * cubic < least_stiffness_3d("fcc", 2.1) < -0.1
    for re in (1.5, 2.3, 2.5, 3.1):
        assert least_stiffness_3d("fcc", re) > -1e-9
        assert least_stiffness_3d("square", re) < -0.1


def test_hexagonal_lattice_is_two_dimensional() -> None:
    with pytest.raises(ValueError, match="2-D only"):
        MPSParameters(dim=3, l0=0.01, lattice="hexagonal")
    with pytest.raises(ValueError, match="2-D only"):
        lattice_reference(3, 0.01, 2.1, "hexagonal")
    with pytest.raises(ValueError, match="allowed"):
        lattice_reference(2, 0.01, 2.1, "triangular")
    with pytest.raises(ValueError, match="square lattice"):
        MPSParameters(dim=2, l0=0.01, lattice="hexagonal", surface="neighbour-count")


def test_fcc_lattice_is_three_dimensional() -> None:
    with pytest.raises(ValueError, match="3-D only"):
        MPSParameters(dim=2, l0=0.01, lattice="fcc")
    with pytest.raises(ValueError, match="3-D only"):
        lattice_reference(2, 0.01, 2.1, "fcc")
    with pytest.raises(ValueError, match="3-D only"):
        water_block(0, 0.04, 0, 0.02, 0.01, lattice="fcc")


def test_surface_threshold_defaults_to_the_lattice() -> None:
    assert MPSParameters(dim=2, l0=0.01).beta == 0.97
    assert MPSParameters(dim=2, l0=0.01, lattice="hexagonal").beta == 0.93
    assert MPSParameters(dim=3, l0=0.01, lattice="fcc").beta == 0.93
    assert MPSParameters(dim=2, l0=0.01, lattice="hexagonal", surface_threshold=0.9).beta == 0.9
    with pytest.raises(ValueError, match="2-D only"):
        tank(0.04, 0.03, 0.01, dim=3, inner_depth=0.02, lattice="hexagonal")


def test_solver_constants_use_the_lattice() -> None:
    positions, kinds = tank(0.05, 0.05, 0.01)
    solver = MPSSolver(MPSParameters(dim=2, l0=0.01), positions, kinds)
    assert solver.constants.n0 == pytest.approx(6.539696961967)
    n0_lap, lam_lap, _ = by_hand(SHELLS_2D_R40, 4.0)
    assert solver.constants.n0_laplacian == pytest.approx(n0_lap)
    assert solver.constants.lambda_laplacian == pytest.approx(lam_lap * 1e-4)


@pytest.mark.parametrize("dim", [2, 3])
def test_cell_list_equals_brute_force(dim: int) -> None:
    rng = np.random.default_rng(7)
    n = 400 if dim == 2 else 600
    position = rng.uniform(0.0, 1.0, (n, dim)) * np.array([1.0, 0.6, 0.8][:dim])
    alive = rng.random(n) > 0.1
    rows = rng.random(n) > 0.3
    radius = 0.13
    start, index, distance = neighbours.neighbour_list(position, alive, rows, radius)
    diff = position[:, None, :] - position[None, :, :]
    r = np.sqrt((diff**2).sum(-1))
    for i in range(n):
        found = sorted(index[start[i] : start[i + 1]].tolist())
        if not (alive[i] and rows[i]):
            assert found == []
            continue
        expected = [j for j in range(n) if j != i and alive[j] and r[i, j] < radius]
        assert found == expected
        got = dict(
            zip(index[start[i] : start[i + 1]], distance[start[i] : start[i + 1]], strict=True)
        )
        for j in expected:
            assert got[j] == pytest.approx(r[i, j], rel=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_verlet_list_cut_to_the_radius_equals_a_fresh_search(dim: int) -> None:
    """A list of candidates searched with radius + skin, cut to the radius after every particle
    moved by less than half the skin, holds exactly the pairs of a fresh search there, at the
    same distances to the last bit (in the candidates' order)."""
    rng = np.random.default_rng(11)
    n = 500
    position = rng.uniform(0.0, 1.0, (n, dim))
    alive = rng.random(n) > 0.1
    rows = rng.random(n) > 0.3
    radius, skin = 0.12, 0.04
    candidates = neighbours.Neighbours(
        *neighbours.neighbour_list(position, alive, alive, radius + skin), radius + skin
    )
    step = rng.normal(size=(n, dim))
    step *= rng.uniform(0.0, 0.5 * skin, (n, 1)) / np.linalg.norm(step, axis=1, keepdims=True)
    moved = position + step
    alive_now = alive & (rng.random(n) > 0.05)  # some die in between
    assert neighbours.largest_displacement(moved, position, alive_now) < 0.5 * skin
    start, index, distance = neighbours.filter_neighbours(
        candidates, moved, alive_now, rows, radius, np.empty(0, np.int32), np.empty(0)
    )
    fresh = neighbours.neighbour_list(moved, alive_now, rows, radius)
    assert np.array_equal(start, fresh[0])
    for i in range(n):
        row = slice(start[i], start[i + 1])
        got = dict(zip(index[row].tolist(), distance[row].tolist(), strict=True))
        want = dict(zip(fresh[1][row].tolist(), fresh[2][row].tolist(), strict=True))
        assert got == want


def test_search_writes_into_a_buffer_that_holds_the_list_and_grows_one_that_does_not() -> None:
    rng = np.random.default_rng(5)
    position = rng.uniform(0.0, 1.0, (300, 3))
    alive = np.ones(300, dtype=np.bool_)
    exact = neighbours.neighbour_list(position, alive, alive, 0.2)
    total = int(exact[0][-1])
    for size in (total + 100, total // 2):
        index_buffer, distance_buffer = np.full(size, -7, np.int32), np.zeros(size)
        start, index, distance = neighbours.search_neighbours(
            position, alive, alive, 0.2, index_buffer, distance_buffer
        )
        assert np.array_equal(start, exact[0])
        assert np.array_equal(index[:total], exact[1])
        assert np.array_equal(distance[:total], exact[2])
        assert np.shares_memory(index, index_buffer) == (size >= total)
        assert index.size >= total


def _outgrown_chunks(
    start: np.ndarray, active: np.ndarray, row_room: int, wave_size: int = 64
) -> list[int]:
    """How many chunks of each wave outgrow their part of the scratch in
    :func:`neighbours.search_in_waves` with the first wave's room ``row_room`` and waves of
    ``wave_size`` chunks, the first at most WAVE_CHUNKS (its rule, from the list's row lengths):
    the test's check that it drives the paths it names."""
    chunk = neighbours.SEARCH_CHUNK
    widths = np.diff(start)[active]
    totals = np.add.reduceat(widths, np.arange(0, widths.size, chunk))
    room, outgrown, first = max(row_room, 1), [], 0
    wave = min(wave_size, neighbours.WAVE_CHUNKS)
    while first < totals.size:
        in_wave = totals[first : first + wave]
        outgrown.append(int(np.sum(in_wave > chunk * room)))
        room = max(room, (int(in_wave.max()) * 5 // 4 + chunk - 1) // chunk)
        first += wave
        wave = wave_size
    return outgrown


@pytest.mark.parametrize("dim", [2, 3])
def test_one_pass_search_gives_the_same_list_whichever_path_its_rows_take(dim: int) -> None:
    """The search fills rows a chunk at a time into scratch, a wave of chunks at a time, and
    searches a chunk that outgrew its scratch again straight into the list. With no room (every
    chunk of the first wave outgrows), little room and the default (chunks of a later wave
    outgrow, after the list has entries), ample room (none do), into buffers too small (grown
    in the first wave, and again in the last one, keeping the waves done), large enough for
    the first wave alone, and large enough for all: the list is the same to the bit, and in
    each row the order of the cells around it (increasing cell number), by index within a
    cell, at the distances of a brute-force search."""
    rng = np.random.default_rng(17)
    n = 7000  # more than three waves of active rows
    position = rng.uniform(0.0, 1.0, (n, dim)) * np.array([1.0, 0.5, 0.4][:dim])
    position[-500:] *= 0.12  # a dense corner in the last rows: the last wave's chunks are wider
    alive = rng.random(n) > 0.05
    rows = rng.random(n) > 0.1
    radius = 0.035 if dim == 3 else 0.02
    active = np.flatnonzero(alive & rows)
    reference = neighbours.neighbour_list(position, alive, rows, radius)
    start = reference[0]
    total = int(start[-1])
    first_wave = int(start[active[neighbours.SEARCH_CHUNK * neighbours.WAVE_CHUNKS]])
    assert len(_outgrown_chunks(start, active, 0)) >= 3
    for row_room in (0, 4, neighbours.FIRST_ROW_ROOM):
        assert _outgrown_chunks(start, active, row_room)[-1] > 0, row_room
    assert _outgrown_chunks(start, active, 0)[0] == neighbours.WAVE_CHUNKS
    assert sum(_outgrown_chunks(start, active, 10_000)) == 0
    # the list cut to the near radius as the rows are copied: near_neighbours' cut
    near_radius = 0.6 * radius
    near = neighbours.near_neighbours(
        neighbours.Neighbours(*reference, radius), near_radius, np.empty(0, np.int32),
        np.empty(0),
    )  # fmt: skip
    near_total = int(near[0][-1])
    assert 0 < near_total < total
    # waves of 7 chunks (the first 7), of 64 (the solver's on 1-2 threads) and of 512 (the
    # first 64, the rest in one wave, its chunks outgrowing after the room was learned)
    assert _outgrown_chunks(start, active, neighbours.FIRST_ROW_ROOM, 512)[-1] > 0
    assert len(_outgrown_chunks(start, active, 0, 512)) == 2
    for row_room, size, wave_size in itertools.product(
        (0, 4, neighbours.FIRST_ROW_ROOM, 10_000),
        (0, first_wave // 2, first_wave + 10, 2 * total),
        (7, neighbours.WAVE_CHUNKS, 512),
    ):
        got = neighbours.search_in_waves(
            position, alive, rows, radius, np.full(size, -1, np.int32), np.zeros(size),
            row_room, near_radius, np.full(size // 3, -1, np.int32), np.zeros(size // 3),
            wave_size,
        )  # fmt: skip
        assert np.array_equal(got[0], start)
        assert np.array_equal(got[1][:total], reference[1])
        assert np.array_equal(got[2][:total], reference[2])
        assert np.array_equal(got[3], near[0])
        assert np.array_equal(got[4][:near_total], near[1][:near_total])
        assert np.array_equal(got[5][:near_total], near[2][:near_total])
    # the order and the distances, by the grid's own rule (cells radius / CELLS_PER_RADIUS
    # wide from the live particles' lowest corner)
    live = position[alive]
    lower = live.min(axis=0)
    shape = ((live.max(axis=0) - lower) * (neighbours.CELLS_PER_RADIUS / radius)).astype(int) + 1
    cell = np.minimum(
        ((position - lower) * (neighbours.CELLS_PER_RADIUS / radius)).astype(int), shape - 1
    )
    number = np.ravel_multi_index(tuple(np.clip(cell, 0, None).T), tuple(shape), order="F")
    for i in rng.choice(active, 60, replace=False):
        r = np.sqrt(((position - position[i]) ** 2).sum(axis=1))
        within = np.flatnonzero(alive & (r < radius))
        within = within[within != i]
        expected = within[np.lexsort((within, number[within]))]
        row = slice(start[i], start[i + 1])
        assert reference[1][row].tolist() == expected.tolist()
        assert np.array_equal(reference[2][row], r[expected])


def test_the_search_takes_waves_as_wide_as_the_threads_and_gives_the_same_list() -> None:
    """A wave holds 32 chunks a thread, at least 64 and at most 512: one parallel loop pair per
    2,048 rows on 1 and 2 threads, per 16,384 from 16 on (NUMBA_NUM_THREADS in a child process,
    whatever its cores). Waves of 1, 7, 64 and 512 chunks (one wave for all the rows) give the
    same list to the bit."""
    assert neighbours.WAVE_CHUNKS == 64 and neighbours.WAVE_CHUNKS_PER_THREAD == 32
    for threads in (1, 2):
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        assert neighbours.wave_chunks() == 64
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    code = "from jellysim.fluid import neighbours; print(neighbours.wave_chunks())"
    for threads, chunks in ((16, "512"), (64, "512")):  # at most 512 (16,384 rows)
        child = subprocess.run(
            [sys.executable, "-c", code], env={**os.environ, "NUMBA_NUM_THREADS": str(threads)},
            capture_output=True, text=True, check=True,
        )  # fmt: skip
        assert child.stdout.split() == [chunks]
    rng = np.random.default_rng(23)
    n = 6000
    position = rng.uniform(0.0, 1.0, (n, 3)) * np.array([1.0, 0.5, 0.4])
    alive = rng.random(n) > 0.05
    rows = rng.random(n) > 0.1
    radius = 0.035
    reference = neighbours.neighbour_list(position, alive, rows, radius)
    near = neighbours.near_neighbours(
        neighbours.Neighbours(*reference, radius), 0.6 * radius, np.empty(0, np.int32),
        np.empty(0),
    )  # fmt: skip
    assert np.count_nonzero(alive & rows) > 2 * neighbours.SEARCH_CHUNK * 64  # several waves
    for wave_size in (1, 7, 64, 512):
        got = neighbours.search_with_near(
            position, alive, rows, radius, np.empty(0, np.int32), np.empty(0), 0.6 * radius,
            np.empty(0, np.int32), np.empty(0), wave_size,
        )  # fmt: skip
        for lists, expected in ((got[:3], reference), (got[3:], near)):
            total = int(expected[0][-1])
            assert 0 < total and np.array_equal(lists[0], expected[0])
            assert np.array_equal(lists[1][:total], expected[1][:total])
            assert np.array_equal(lists[2][:total], expected[2][:total])


def test_the_fluid_kernels_fastmath_flags_are_linalgs() -> None:
    """kernels.py and deflation.py write linalg's fastmath flags out (a cached kernel is
    compiled again only when its own file changes): the copies are the same, contraction
    alone (no reassociation: sums in the written order, docs/decisions.md)."""
    from numba.core.registry import CPUDispatcher

    from jellysim.fluid import deflation, kernels, linalg

    assert kernels.FAST == deflation.FAST == linalg.FAST == {"contract"}
    # and every compiled function of the three that asks for fastmath asks for these
    flagged = []
    for module in (kernels, deflation, linalg):
        for name, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.__module__ == module.__name__:
                flags = value.targetoptions.get("fastmath")
                if flags:
                    assert set(flags) == {"contract"}, name
                    flagged.append(name)
    assert {"multiply", "explicit_stage", "pressure_correction", "_smooth"} <= set(flagged)


def blob(dim: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A free, jittered fluid block (no walls) with random velocities."""
    l0 = 0.01
    position = water_block(0, 0.12, 0, 0.1, l0, *((0, 0.06) if dim == 3 else ()))
    rng = np.random.default_rng(seed)
    position = position + rng.uniform(-0.2, 0.2, position.shape) * l0
    velocity = rng.normal(0.0, 0.1, position.shape)
    return position, velocity, np.full(position.shape[0], FLUID, dtype=np.int8)


@pytest.mark.parametrize("dim", [2, 3])
def test_explicit_stage_conserves_fluid_momentum_without_gravity(dim: int) -> None:
    """Viscosity in the gather form: pair (i, j) adds nu C w (u_j - u_i) to i and the opposite to
    j (same C = 2D/(lambda n0) for all), so with only fluid particles and no body force the total
    momentum sum_i u_i (equal masses) is unchanged to round-off."""
    position, velocity, kind = blob(dim, 1)
    params = MPSParameters(dim=dim, l0=0.01, kinematic_viscosity=0.05)
    solver = MPSSolver(params, position, kind)
    nb = neighbours.Neighbours(
        *neighbours.neighbour_list(position, solver.alive, solver.alive, solver.search_radius),
        solver.search_radius,
    )
    out_x = np.empty_like(position)
    out_u = np.empty_like(velocity)
    zero = np.zeros_like(velocity)
    dt = 1e-3
    kernels.explicit_stage(
        position, velocity, kind, solver.alive, nb, solver.constants, zero, dt, out_x, out_u
    )
    change = np.abs(out_u - velocity).sum(axis=0)
    assert np.all(change > 1e-3)  # the viscosity does act
    np.testing.assert_allclose(out_u.sum(axis=0), velocity.sum(axis=0), rtol=0, atol=1e-12)
    np.testing.assert_allclose(out_x, position + dt * out_u, rtol=0, atol=1e-15)


@pytest.mark.parametrize("dim", [2, 3])
def test_collision_conserves_momentum(dim: int) -> None:
    position, velocity, kind = blob(dim, 2)
    rng = np.random.default_rng(3)
    position = position + rng.uniform(-0.3, 0.3, position.shape) * 0.01  # many close pairs
    alive = np.ones(kind.shape[0], dtype=np.bool_)
    radius = 0.5 * 0.01
    nb = neighbours.Neighbours(*neighbours.neighbour_list(position, alive, alive, 0.021), 0.021)
    out_x = np.empty_like(position)
    out_u = np.empty_like(velocity)
    kernels.collision(position, velocity, kind, alive, nb, radius, 0.2, 1e-3, out_x, out_u)
    assert np.abs(out_u - velocity).max() > 1e-3  # collisions happened
    np.testing.assert_allclose(out_u.sum(axis=0), velocity.sum(axis=0), rtol=0, atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_conservative_gradient_conserves_momentum_and_the_standard_does_not(dim: int) -> None:
    """Eq. (F10c) [Khayyer & Gotoh 2008]: each pair's coefficient (p_i + p_j) - (p_min,i +
    p_min,j) is symmetric and r_j - r_i antisymmetric, so with only fluid particles (equal
    masses) the pressure's impulses cancel pair by pair: sum_i u_i is unchanged to round-off.
    The minimum-pressure gradient of Eq. (F10) weighs a pair by p_j - p_min,i from i's side and
    p_i - p_min,j from j's: it changes the momentum, by far more than round-off."""
    position, velocity, kind = blob(dim, 4)
    rng = np.random.default_rng(5)
    pressure = rng.uniform(0.0, 500.0, kind.shape[0])
    solver = MPSSolver(MPSParameters(dim=dim, l0=0.01), position, kind)
    nb = neighbours.Neighbours(
        *neighbours.neighbour_list(position, solver.alive, solver.alive, solver.search_radius),
        solver.search_radius,
    )
    dt = 1e-3
    change = {}
    for name, kernel in (
        ("conservative", kernels.conservative_pressure_correction),
        ("standard", kernels.pressure_correction),
    ):
        out_x = np.empty_like(position)
        out_u = np.empty_like(velocity)
        kernel(position, velocity, pressure, kind, solver.alive, nb, solver.constants, dt, out_x,
               out_u)  # fmt: skip
        assert np.abs(out_u - velocity).max() > 1e-3  # the pressure does act
        np.testing.assert_allclose(out_x, position + dt * (out_u - velocity), rtol=0, atol=1e-15)
        change[name] = np.abs((out_u - velocity).sum(axis=0)).max()
    assert change["conservative"] < 1e-12
    assert change["standard"] > 1e-3


def test_tank_geometry() -> None:
    l0 = 0.01
    positions, kinds = tank(0.1, 0.05, l0, wall_layers=1, dummy_layers=2)
    # 16 x 8 cells with the 10 x 5 inside removed
    assert positions.shape == (16 * 8 - 10 * 5, 2)
    walls = positions[kinds == WALL]
    assert np.isclose(walls[:, 1].min(), -0.5 * l0) and np.isclose(walls[:, 0].min(), -0.5 * l0)
    assert np.isclose(walls[:, 0].max(), 0.1 + 0.5 * l0)
    assert (kinds == DUMMY).sum() == 16 * 8 - 12 * 6
    fluid = water_block(0, 0.1, 0, 0.05, l0)
    assert fluid.shape == (50, 2)
    gap = np.sqrt(((fluid[:, None] - positions[None]) ** 2).sum(-1)).min()
    assert gap == pytest.approx(l0)
    positions3, kinds3 = tank(0.04, 0.03, l0, dim=3, inner_depth=0.02)
    assert positions3.shape == (10 * 8 * 6 - 4 * 2 * 3, 3)
    assert water_block(0, 0.04, 0, 0.02, l0, 0, 0.03).shape == (24, 3)


def test_hexagonal_tank_geometry() -> None:
    """The hexagonal tank and its water are one lattice: every particle's nearest neighbour is
    l0 away, each row holds width / l0 fluid particles (pairs of rows centred), the walls are
    the sites at most l0 behind the side faces and one row under the floor, and walls with dummies
    complete the neighbourhood of every fluid particle away from the free surface (n = n0)."""
    l0 = 0.005
    width, depth = 0.2, 0.1
    row = math.sqrt(3.0) / 2.0 * l0
    walls, kinds = tank(width, 0.15, l0, lattice="hexagonal")
    fluid = water_block(0.0, width, 0.0, depth, l0, lattice="hexagonal")
    assert filled_height(depth, l0, "hexagonal") == pytest.approx(23 * row)
    assert fluid.shape == (40 * 23, 2)  # 40 a row (width / l0), round(0.1 / row) = 23 rows
    assert fluid[:, 0].min() > 0 and fluid[:, 0].max() < width and fluid[:, 1].max() < depth
    everything = np.vstack([fluid, walls])
    distance = np.sqrt(((everything[:, None] - everything[None]) ** 2).sum(-1))
    np.fill_diagonal(distance, np.inf)
    np.testing.assert_allclose(distance.min(axis=1), l0, rtol=1e-12)
    rows = np.rint(fluid[:, 1] / row - 0.5).astype(int)
    assert np.array_equal(np.bincount(rows), np.full(23, 40))
    for j in range(23):  # rows alternately l0 / 4 left and right of the middle
        assert fluid[rows == j, 0].mean() == pytest.approx(0.5 * width + (j % 2 - 0.5) * 0.5 * l0)
    behind = np.maximum(np.maximum(-walls[:, 0], walls[:, 0] - width), -walls[:, 1])
    assert np.all((behind[kinds == WALL] > 0) & (behind[kinds == WALL] <= l0))
    assert np.all(behind[kinds == DUMMY] > l0)
    # number density of the fluid particles at r_e = 2.1 l0
    n = np.where(distance < 2.1 * l0, 2.1 * l0 / distance - 1.0, 0.0).sum(axis=1)[: len(fluid)]
    n0 = lattice_reference(2, l0, 2.1, "hexagonal").n0
    inside = fluid[:, 1] < depth - 2.5 * l0
    np.testing.assert_allclose(n[inside], n0)
    # The surface threshold 0.93 splits the top two rows away from the side walls: the top row
    # misses four neighbours within 2.1 l0 (0.641 n0), the second row three (0.962 n0, above
    # 0.93 but under the square lattice's 0.97).
    middle = np.abs(fluid[:, 0] - 0.5 * width) < 0.25 * width
    top, second = fluid[:, 1] > depth - row, np.abs(fluid[:, 1] - (depth - 1.5 * row)) < 0.1 * row
    np.testing.assert_allclose(n[top & middle] / n0, 0.6407, atol=1e-4)
    np.testing.assert_allclose(n[second & middle] / n0, 0.9618, atol=1e-4)


def test_fcc_tank_geometry() -> None:
    """The fcc tank and its water are one lattice: every particle's nearest neighbour is l0
    away and a fluid particle away from the surface has twelve; each layer's rows hold
    width / l0 fluid particles; the walls are the sites less than l0 behind a face, the dummies
    those less than 3 l0 behind; walls with dummies complete the neighbourhood of every fluid
    particle away from the free surface (n = n0); the top layer has 0.687 n0 and the second
    0.964 n0 (above the threshold 0.93) away from the walls."""
    l0 = 0.005
    width, depth, height = 0.06, 0.04, 0.03
    layer = math.sqrt(2.0 / 3.0) * l0
    walls, kinds = tank(width, 0.045, l0, dim=3, inner_depth=depth, lattice="fcc")
    fluid = water_block(0.0, width, 0.0, depth, l0, 0.0, height, lattice="fcc")
    assert filled_height(height, l0, "fcc") == pytest.approx(7 * layer)  # round(0.03 / layer)
    lower, upper = fluid.min(axis=0), fluid.max(axis=0)
    assert np.all(lower > 0) and upper[0] < width and upper[1] < depth and upper[2] < height
    layers = np.rint(fluid[:, 2] / layer - 0.5).astype(int)
    assert np.array_equal(np.unique(layers), np.arange(7))
    rows = np.rint(fluid[:, 1] / (math.sqrt(3.0) / 2.0 * l0) - layers / 3.0 - 1.0 / 6.0)
    for key in set(zip(layers, rows.astype(int), strict=True)):
        assert np.sum((layers == key[0]) & (rows == key[1])) == 12  # width / l0 a row
    everything = np.vstack([fluid, walls])
    distance = np.sqrt(((fluid[:, None] - everything[None]) ** 2).sum(-1))
    distance[np.arange(len(fluid)), np.arange(len(fluid))] = np.inf
    np.testing.assert_allclose(distance.min(axis=1), l0, rtol=1e-12)
    count = (distance < 1.0001 * l0).sum(axis=1)
    inside = fluid[:, 2] < height - 2 * layer
    assert np.all(count[inside] == 12)
    x, y, z = walls.T
    behind = np.max(np.column_stack([-x, x - width, -y, y - depth, -z]), axis=1)
    assert np.all((behind[kinds == WALL] > 0) & (behind[kinds == WALL] < l0))
    assert np.all((behind[kinds == DUMMY] >= l0) & (behind[kinds == DUMMY] < 3 * l0))
    n = np.where(distance < 2.1 * l0, 2.1 * l0 / distance - 1.0, 0.0).sum(axis=1)
    n0 = lattice_reference(3, l0, 2.1, "fcc").n0
    np.testing.assert_allclose(n[fluid[:, 2] < height - 3 * layer] / n0, 1.0, rtol=1e-12)
    away = np.all(
        (fluid[:, :2] > 2.5 * l0) & (fluid[:, :2] < [width - 2.5 * l0, depth - 2.5 * l0]), 1
    )
    np.testing.assert_allclose(n[away & (layers == 6)] / n0, 0.6874, atol=1e-4)
    np.testing.assert_allclose(n[away & (layers == 5)] / n0, 0.9639, atol=1e-4)


@pytest.mark.parametrize("spacing", [0.0536667, 0.161 / 3, 0.0536665])
def test_a_spacing_the_scene_check_accepts_builds_its_tank(spacing: float) -> None:
    """The scene check (config/load.py) and the tank's lattice (geometry._cells) take the same
    lengths as whole numbers of spacings: spheric-test2's 3.22 m at a spacing typed to seven
    figures (docs/fluid.md's CI run, 0.0536667 for 0.161 / 3) builds 60 cells across, where it
    used to pass the check and fail in the lattice ("internal error"); one 4e-6 off is refused by
    the check as bad input, never as an internal error."""
    from jellysim.config import load_scene
    from jellysim.errors import InputError
    from jellysim.simulation.fluid import FluidSimulation

    overrides = {"fluid.spacing": spacing, "duration": 0.02}
    if abs(3.22 / spacing - 60) > 6e-5:
        with pytest.raises(InputError, match="not a whole number"):
            load_scene("spheric-test2", overrides)
        return
    solver = FluidSimulation(load_scene("spheric-test2", overrides)).solver
    fluid = solver.position[solver.kind == FLUID]
    assert fluid[:, 0].max() < 3.22 and 3.22 - fluid[:, 0].max() < spacing


def _gradient_acceleration(
    positions: np.ndarray,
    pressure: np.ndarray,
    corrected: bool,
    surface: np.ndarray | None = None,
    lattice: str = "square",
) -> np.ndarray:
    """-grad p / rho (m/s2) of every particle of a fluid block, by one pressure correction of
    dt = 1 s from rest (Eq. F10 or F10a; with ``surface``, F10b on those particles)."""
    n, dim = positions.shape
    kinds = np.full(n, FLUID, dtype=np.int8)
    solver = MPSSolver(MPSParameters(dim=dim, l0=0.01, lattice=lattice), positions, kinds)
    nb = solver.neighbours(solver.alive)
    out_position = np.empty_like(positions)
    out_velocity = np.empty_like(positions)
    kernels.pressure_correction(
        positions, np.zeros_like(positions), pressure, kinds, solver.alive, nb,
        solver.constants, 1.0, out_position, out_velocity, corrected, surface,
    )  # fmt: skip
    return out_velocity


@pytest.mark.parametrize("dim", [2, 3])
def test_corrected_gradient_is_exact_for_hydrostatic_pressure_at_the_free_surface(dim) -> None:
    """Eq. (F10a) [Khayyer & Gotoh 2011, J. Comput. Phys. 230, 3093]: on a block of water with
    the hydrostatic pressure rho g (top - z), away from the sides, the pressure force balances
    gravity exactly on the top layer, whose neighbourhood is one-sided, and inside. The
    uncorrected gradient (F10) balances only half of gravity on the top layer (its neighbours
    below carry half the lattice's second moment). In between, the layer under the top misses
    one far neighbour, and the minimum-pressure term (p_i - p_min) sum_j r_ij w / r^2 is not
    zero there: 0.5 % in 2-D."""
    l0, rho, g = 0.01, 1000.0, 9.81
    if dim == 2:
        positions = water_block(0.0, 0.12, 0.0, 0.08, l0)
    else:
        positions = water_block(0.0, 0.08, 0.0, 0.08, l0, 0.0, 0.06)
    up = positions[:, -1]
    top = up.max()
    pressure = rho * g * (top - up)
    inner = np.all(
        (positions[:, :-1] > 3 * l0) & (positions[:, :-1] < positions[:, :-1].max() - 2.5 * l0),
        axis=1,
    ) & (up > 3 * l0)
    surface = inner & (up == top)
    assert surface.sum() >= 4
    corrected = _gradient_acceleration(positions, pressure, corrected=True)
    standard = _gradient_acceleration(positions, pressure, corrected=False)
    np.testing.assert_allclose(corrected[surface, -1], g, rtol=1e-10)
    np.testing.assert_allclose(corrected[inner, -1], g, rtol=0.01)
    np.testing.assert_allclose(corrected[inner, :-1], 0.0, atol=1e-10)
    np.testing.assert_allclose(standard[surface, -1], 0.5 * g, rtol=1e-10)
    deep = inner & (up < top - 2.5 * l0)
    np.testing.assert_allclose(corrected[deep, -1], g, rtol=1e-10)
    np.testing.assert_allclose(standard[deep], corrected[deep], atol=1e-10)


def test_corrected_gradient_falls_back_where_the_neighbourhood_is_degenerate() -> None:
    """Two lone particles (a splash): the moment matrix is singular (det 0 < 0.3), so the
    gradient stays the uncorrected one, finite."""
    positions = np.array([[0.0, 0.0], [0.01, 0.0]])
    pressure = np.array([0.0, 100.0])
    corrected = _gradient_acceleration(positions, pressure, corrected=True)
    standard = _gradient_acceleration(positions, pressure, corrected=False)
    assert np.all(np.isfinite(corrected))
    np.testing.assert_array_equal(corrected, standard)
    assert corrected[0, 0] < 0.0  # pushed away from the higher pressure


@pytest.mark.parametrize(("dim", "lattice"), [(2, "square"), (2, "hexagonal"), (3, "square")])
def test_surface_repulsion_is_tangential_and_restores_the_spacing(dim, lattice) -> None:
    """Eq. (F10b) (docs/theory/fluid.md): on the top row of a block with the hydrostatic
    pressure rho g (top - y), away from the sides, the repulsion adds nothing (its push along
    the row cancels by symmetry and its normal part is removed), so Khayyer & Gotoh's exact
    balance of gravity stands. A top particle moved along the row towards a neighbour is pushed
    back in proportion to the move: a spring along the surface, which the corrected gradient
    alone lacks (it is exact for the linear pressure whatever the spacing, so it gives no push
    back). Its vertical balance changes at second order only: within 1 % for a move of
    0.05 l0 (measured: 0.8 % on the square lattice, 0.5 % on the hexagonal one). In 3-D the
    same holds on the cubic lattice's top layer."""
    l0, rho, g = 0.01, 1000.0, 9.81
    if dim == 2:
        positions = water_block(0.0, 0.2, 0.0, 0.1, l0, lattice=lattice)
    else:
        positions = water_block(0.0, 0.16, 0.0, 0.16, l0, 0.0, 0.06)
    centre = positions[:, :-1].max(axis=0) / 2 + 0.25 * l0
    y = positions[:, -1]
    top = y.max()
    row = y > top - 0.1 * l0
    off = np.sqrt(((positions[:, :-1] - centre) ** 2).sum(axis=1))
    middle = np.arange(len(y)) == np.argmin(np.where(row, off, 1.0))
    away = off < centre.min() - 4.5 * l0  # the normal's radius (4 l0) clear of the sides
    pressure = rho * g * (top - y)
    plain = _gradient_acceleration(positions, pressure, True, lattice=lattice)
    repelled = _gradient_acceleration(positions, pressure, True, row, lattice)
    np.testing.assert_allclose(repelled[away], plain[away], atol=1e-9 * g)
    pushes = []
    for move in (0.02, 0.05):
        moved = positions.copy()
        moved[middle, 0] += move * l0
        plain = _gradient_acceleration(moved, pressure, True, lattice=lattice)[middle][0]
        repelled = _gradient_acceleration(moved, pressure, True, row, lattice)[middle][0]
        assert abs(plain[0]) < 1e-6 * g  # no push back without F10b
        assert repelled[0] < -0.01 * g
        assert repelled[-1] == pytest.approx(g, rel=0.01)
        assert np.all(np.abs(repelled[1:-1]) < 1e-9 * g)  # nothing across the move (3-D)
        pushes.append(-repelled[0])
    assert pushes[1] / pushes[0] == pytest.approx(2.5, rel=0.05)


def test_surface_repulsion_skips_a_particle_without_neighbours() -> None:
    """A lone surface particle has no normal: F10b leaves its (zero) gradient alone."""
    positions = np.array([[0.0, 0.0], [0.05, 0.0]])
    pressure = np.array([0.0, 0.0])
    surface = np.array([True, True])
    accelerations = _gradient_acceleration(positions, pressure, True, surface)
    np.testing.assert_array_equal(accelerations, 0.0)


def test_commit_step_takes_the_corrected_state_and_kills_escaped_fluid_only() -> None:
    """kernels.commit_step against the rule it replaced (NumPy, serial): the corrected arrays
    become the state; a live fluid particle outside the domain or with a non-finite position
    or velocity dies with velocity and pressure 0; walls, dummies and the dead are left."""
    rng = np.random.default_rng(7)
    n = 400
    kind = rng.choice(np.array([FLUID, WALL, DUMMY], dtype=np.int8), n)
    alive = rng.random(n) > 0.05
    new_position = rng.uniform(-0.1, 1.1, (n, 3))  # some outside [0, 1]^3
    new_velocity = rng.normal(size=(n, 3))
    new_position[rng.random(n) < 0.03, 1] = np.nan
    new_velocity[rng.random(n) < 0.03, 2] = np.inf
    pressure = rng.random(n)
    low, high = np.zeros(3), np.ones(3)

    expected_alive = alive.copy()
    finite = np.isfinite(new_position).all(1) & np.isfinite(new_velocity).all(1)
    inside = np.all((new_position >= low) & (new_position <= high), 1)
    dying = alive & (kind == FLUID) & ~(finite & inside)
    expected_alive[dying] = False
    expected_velocity = new_velocity.copy()
    expected_velocity[dying] = 0.0
    expected_pressure = pressure.copy()
    expected_pressure[dying] = 0.0
    assert 10 < dying.sum() < n // 2  # the draw exercises both outcomes

    position, velocity = np.zeros((n, 3)), np.zeros((n, 3))
    dead = kernels.commit_step(
        position, velocity, new_position, new_velocity, pressure, kind, alive, low, high
    )
    assert dead == int((~expected_alive).sum())
    np.testing.assert_array_equal(position, new_position)
    np.testing.assert_array_equal(velocity, expected_velocity)
    np.testing.assert_array_equal(pressure, expected_pressure)
    np.testing.assert_array_equal(alive, expected_alive)
