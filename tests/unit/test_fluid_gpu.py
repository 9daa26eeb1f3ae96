"""The MPS fluid's GPU path (jellysim.fluid.gpu) against the CPU path, on tiny tanks.

CI has no GPU: conftest.py turns on Numba's CUDA simulator, which runs the very kernels in
Python threads (slowly: a few hundred particles, a step or two). Both paths solve the pressure
to a relative residual of 1e-12 here, so they agree to the round-off of their different sums
and solvers; a wrong term in any equation shows as a difference of order one in its effect.
The bounds (measured differences were ~1e-17 m, ~1e-15 m/s and ~1e-13 of the largest pressure
in 2-D and 3-D): positions 1e-8 l0, velocities 1e-6 of g dt, pressures 1e-6 of the largest.

The same tests on a real GPU, at full size: tests/gpu (make test-gpu).
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys

import numpy as np
import pytest

from jellysim.fluid import gpu
from jellysim.fluid.geometry import DUMMY, FLUID, WALL, tank, water_block
from jellysim.fluid.mps import MPSParameters, MPSSolver

pytestmark = pytest.mark.skipif(
    not gpu.simulated(), reason="the CUDA simulator is off (make test-gpu runs tests/gpu)"
)

L0 = 0.01


def _particles(dim: int, lattice: str) -> tuple[np.ndarray, np.ndarray]:
    """A tank with a water column against its left wall (a small dam break)."""
    if dim == 2:
        walls, kinds = tank(0.08, 0.08, L0, dim=2, lattice=lattice)
        water = water_block(0.0, 0.04, 0.0, 0.06, L0, lattice=lattice)
    else:
        walls, kinds = tank(0.04, 0.05, L0, dim=3, inner_depth=0.03, lattice=lattice)
        water = water_block(0.0, 0.02, 0.0, 0.03, L0, 0.0, 0.04, lattice=lattice)
    positions = np.concatenate([water, walls])
    return positions, np.concatenate([np.full(len(water), FLUID, np.int8), kinds])


MIXED = {
    "source": "mixed",
    "gradient": "corrected",
    "surface": "either-density",
    "surface_repulsion": True,
    "collision_distance": 0.8,
}
CASES = {
    # hydrostatic-2d's model and lattice, two steps (the warm start carried over)
    "mixed-2d": (2, "hexagonal", MIXED, 2),
    # the standard source with the pair-wise gradient
    "conservative-2d": (2, "square", {"gradient": "conservative"}, 2),
    # the paper's standard scheme with the neighbour-count surface
    "standard-2d": (2, "square", {"surface": "neighbour-count"}, 2),
    # hydrostatic-3d's model on the fcc lattice
    "mixed-3d": (3, "fcc", MIXED, 1),
    # the matrix in single precision on both (fluid.matrix_precision)
    "mixed-2d-single": (2, "hexagonal", {**MIXED, "matrix_precision": "single"}, 2),
}


def _pair(case: str) -> tuple[MPSSolver, gpu.GPUSolver, np.ndarray, int]:
    dim, lattice, options, steps = CASES[case]
    positions, kinds = _particles(dim, lattice)
    params = MPSParameters(dim=dim, l0=L0, lattice=lattice, tolerance=1e-12, **options)
    cpu = MPSSolver(params, positions, kinds)
    return cpu, gpu.GPUSolver(params, positions, kinds), kinds, steps


def _stirred(cpu: MPSSolver) -> dict[str, np.ndarray]:
    """``cpu``'s state (the 2-D column, hexagonal) with the water stirred (viscosity at work from
    the first step), the top particle of the column's middle thrown down at 3 m/s onto the one
    below it, thrown up (they close to within the collision distance in a step), and a surface
    particle pushed into the water."""
    state = cpu.state_arrays()
    fluid = np.flatnonzero(cpu.kind == FLUID)
    rng = np.random.default_rng(3)
    state["velocity"][fluid] = rng.normal(0.0, 0.02, (fluid.size, cpu.params.dim))
    x = state["position"][fluid]
    middle = fluid[np.abs(x[:, 0] - np.median(x[:, 0])) < 0.3 * L0]
    top = middle[np.argmax(state["position"][middle, -1])]
    below = middle[np.argsort(state["position"][middle, -1])[-2]]
    state["velocity"][top, -1] = -3.0
    state["velocity"][below, -1] = 3.0
    # a top-row particle near the column's right edge pushed down at 1 m/s: n* >= beta n0 at
    # r* though n^k < beta n0 (found by trying the surface particles on the CPU path)
    edge = fluid[np.argmin(np.linalg.norm(x - np.array([0.0325, 0.0563]), axis=1))]
    assert np.linalg.norm(state["position"][edge] - [0.0325, 0.0563]) < 0.1 * L0
    state["velocity"][edge, -1] = -1.0
    return state


def test_the_kernels_constants_are_their_sources() -> None:
    """gpu_kernels writes the constants its kernels read (so that an edit of one changes that
    file and Numba compiles the cached kernels again): they are the values the rest of the
    package uses."""
    from jellysim.fluid import geometry, gpu_kernels, kernels, neighbours

    assert gpu_kernels.BLOCK == gpu.BLOCK
    assert gpu_kernels.CELLS_PER_RADIUS == neighbours.CELLS_PER_RADIUS
    team = gpu.COARSE_TEAM_SIMULATED  # a power of two dividing a block: its teams' trees
    assert gpu.BLOCK % team == 0 and team & (team - 1) == 0 and team > 1
    kinds = (gpu_kernels.FLUID, gpu_kernels.WALL, gpu_kernels.DUMMY)
    assert kinds == (geometry.FLUID, geometry.WALL, geometry.DUMMY)
    assert gpu_kernels.CORRECTION_MIN_DETERMINANT == kernels.CORRECTION_MIN_DETERMINANT


def test_gpu_step_matches_cpu_with_collisions_and_viscosity() -> None:
    """A stirred column (:func:`_stirred`) with hydrostatic-2d's model: the collision, the
    viscous term and the either-density surface all act in the step (checked on the CPU: with
    another restitution or the standard surface criterion its result is another), and the GPU
    gives the CPU's step."""
    cpu, device, kinds, _ = _pair("mixed-2d")
    state = _stirred(cpu)
    cpu.restore(state)
    device.restore(state)
    dt = cpu.stable_dt()
    assert device.stable_dt() == pytest.approx(dt, rel=1e-14)
    cpu_stats = cpu.step(dt)
    gpu_stats = device.step(dt)
    fluid = kinds == FLUID
    assert gpu_stats.surface == cpu_stats.surface
    assert np.abs(device.position[fluid] - cpu.position[fluid]).max() <= 1e-8 * L0
    assert np.abs(device.velocity[fluid] - cpu.velocity[fluid]).max() <= 1e-6 * 9.81 * dt
    assert np.abs(device.pressure - cpu.pressure).max() <= 1e-6 * cpu.pressure.max()
    for change, what in (
        ({"collision_restitution": 1.0}, "velocity"),
        ({"surface": "standard"}, "surface"),
        ({"kinematic_viscosity": 0.0}, "velocity"),
    ):
        other = MPSSolver(dataclasses.replace(cpu.params, **change), state["position"], kinds)
        other.restore(state)
        stats = other.step(dt)
        if what == "surface":
            assert stats.surface != cpu_stats.surface, change
        else:
            apart = np.abs(other.velocity[fluid] - cpu.velocity[fluid]).max()
            assert apart > 1e3 * 1e-6 * 9.81 * dt, change


def test_a_step_is_its_six_phases_in_six_launches(monkeypatch) -> None:
    """A step launches its six phases and nothing else, each one cooperative kernel (the two
    searches, the explicit phase, the assembly, the CG, the correction: docs/decisions.md, "A
    GPU step in six launches"), and reads five small arrays back (each search's widest row,
    the solve's residual, the counters, the extent). The next step's dt is the correction
    phase's extent: stable_dt launches nothing then, and gives what its own kernel gives."""
    from numba.cuda.simulator.cudadrv.devicearray import FakeCUDAArray

    positions, kinds = _particles(2, "square")
    device = gpu.GPUSolver(MPSParameters(dim=2, l0=L0), positions, kinds)
    dt = device.stable_dt()
    launched: list[str] = []

    class Counting(dict):
        def __getitem__(self, name: str):
            launched.append(name)
            return super().__getitem__(name)

    reads = []
    download = FakeCUDAArray.copy_to_host
    monkeypatch.setattr(device, "k", Counting(device.k))
    monkeypatch.setattr(
        FakeCUDAArray, "copy_to_host", lambda self, *a, **k: reads.append(1) or download(self)
    )
    device.step(dt)
    phases = ["explicit_phase", "assembly_phase", "conjugate_gradient", "correction_phase"]
    assert launched == ["neighbour_search", phases[0], "neighbour_search", *phases[1:]]
    assert len(reads) == 5
    launched.clear()
    after_step = device.stable_dt()
    assert launched == []
    device._extent_host = None  # as after a restore: the extent kernel
    assert device.stable_dt() == after_step
    assert launched == ["extent"]


@pytest.mark.parametrize("case", list(CASES))
def test_gpu_step_matches_cpu(case: str) -> None:
    """Each case's steps on both paths. In "standard-2d" an external force density acts too,
    a shear up to half of gravity's (each row its own), given to the GPU as a device array (as
    the soft bell's springs give theirs) and to the CPU as a host array."""
    cpu, device, kinds, steps = _pair(case)
    fluid = kinds == FLUID
    force = None
    if case == "standard-2d":
        force = np.zeros_like(cpu.position)  # N/m3
        force[:, 0] = 5e3 * cpu.position[:, 1] / cpu.position[:, 1].max()
    single = case.endswith("-single")  # both paths' matrices in single precision
    assert (device._coefficient.dtype == np.float32) == single
    assert (cpu._matrix_buffers[1].dtype == np.float32) == single
    for _ in range(steps):
        dt = cpu.stable_dt()
        assert device.stable_dt() == pytest.approx(dt, rel=1e-14)
        cpu_stats = cpu.step(dt, force)
        gpu_stats = device.step(dt, None if force is None else gpu.cuda.to_device(force))
        assert gpu_stats.surface == cpu_stats.surface
        assert gpu_stats.residual <= 1e-12
        g_dt = 9.81 * dt
        assert np.abs(device.position[fluid] - cpu.position[fluid]).max() <= 1e-8 * L0
        assert np.abs(device.velocity[fluid] - cpu.velocity[fluid]).max() <= 1e-6 * g_dt
        largest = cpu.pressure.max()
        assert np.abs(device.pressure - cpu.pressure).max() <= 1e-6 * largest
        np.testing.assert_allclose(device.number_density, cpu.number_density, rtol=1e-12)
        assert device.alive.all() and device.time == cpu.time
    # the comparison is of steps that did something: the water moved, under a pressure
    assert np.abs(device.velocity[fluid]).max() > 0.5 * g_dt
    assert largest > 0.0


def test_a_single_precision_matrix_rounds_the_entries_and_keeps_each_rows_excess() -> None:
    """fluid.matrix_precision = "single": after one step from the same state (the PPE is
    assembled at r*, which no pressure has touched yet), the single-precision coefficients are
    the double ones rounded, slot for slot, and each row's diagonal less its coefficients, the
    excess that its free-surface neighbours and the compressibility give, is the double one
    to the round-off of the sums (a diagonal rounded as well would leave it 6e-8 of the
    diagonal off, as large as the whole excess of an inner row)."""
    dim, lattice, options, _ = CASES["mixed-2d"]
    positions, kinds = _particles(dim, lattice)
    systems = {}
    for precision in ("double", "single"):
        params = MPSParameters(
            dim=dim, l0=L0, lattice=lattice, tolerance=1e-12, matrix_precision=precision,
            **options,
        )  # fmt: skip
        device = gpu.GPUSolver(params, positions, kinds)
        device.step(device.stable_dt())
        count = device._list_count.copy_to_host()
        unknown = device._unknown.copy_to_host() == 1
        filled = np.arange(device.width)[:, None] < count[None, :]
        coefficient = np.where(filled, device._coefficient.copy_to_host(), 0.0)
        systems[precision] = coefficient, device._diagonal.copy_to_host(), unknown
    (c64, d64, unknown), (c32, d32, unknown32) = systems["double"], systems["single"]
    np.testing.assert_array_equal(unknown, unknown32)
    assert c32.dtype == np.float32 and c64.dtype == np.float64
    np.testing.assert_array_equal(c64[:, unknown].astype(np.float32), c32[:, unknown])
    assert np.any(c64[:, unknown] != c32[:, unknown])
    excess64 = d64[unknown] - c64[:, unknown].sum(axis=0)
    excess32 = d32[unknown] - c32[:, unknown].astype(np.float64).sum(axis=0)
    np.testing.assert_allclose(excess32, excess64, rtol=0, atol=1e-12 * d64.max())
    assert np.abs(d32[unknown] - d64[unknown]).max() > 1e-9 * d64.max()  # not merely copied


def test_a_device_force_of_the_wrong_shape_is_refused_before_the_step() -> None:
    """An external force given on the GPU (the soft bell's springs) is checked as a host one:
    a wrong shape is a ValueError, and the state is not touched."""
    _, device, _, _ = _pair("standard-2d")
    before = device.state_arrays()
    force = gpu.cuda.to_device(np.zeros((device.n - 1, 2)))
    with pytest.raises(ValueError, match="external_force must be"):
        device.step(1e-4, force)
    after = device.state_arrays()
    for name, value in before.items():
        np.testing.assert_array_equal(after[name], value)


def test_gpu_runs_are_the_same_to_the_bit_and_resume_across_devices() -> None:
    """Two GPU runs of a step agree bit for bit (no floating-point atomic sums); a GPU run
    resumed from its checkpoint in a new solver steps as the run itself; a GPU state resumes
    on the CPU and a CPU state on the GPU (the checkpoint's arrays are the same)."""
    cpu, first, kinds, _ = _pair("standard-2d")
    positions = cpu.position.copy()
    second = gpu.GPUSolver(first.params, positions, kinds)
    dt = cpu.stable_dt()
    first.step(dt)
    second.step(dt)
    for name, value in first.state_arrays().items():
        np.testing.assert_array_equal(second.state_arrays()[name], value, err_msg=name)
    resumed = gpu.GPUSolver(first.params, positions, kinds)
    resumed.restore(first.state_arrays())
    first.step(dt)
    resumed.step(dt)
    for name, value in first.state_arrays().items():
        np.testing.assert_array_equal(resumed.state_arrays()[name], value, err_msg=name)
    # GPU checkpoint, CPU resume; and back
    cpu.restore(first.state_arrays())
    for name, value in first.state_arrays().items():
        np.testing.assert_array_equal(cpu.state_arrays()[name], value, err_msg=name)
    cpu.step(dt)
    second.restore(cpu.state_arrays())
    for name, value in cpu.state_arrays().items():
        np.testing.assert_array_equal(second.state_arrays()[name], value, err_msg=name)
    # the host copies are read-only: a write would not reach the GPU
    with pytest.raises(ValueError, match="read-only"):
        second.velocity[0, 0] = 1.0


def _still_square(
    width: float, solver: str, precision: str = "double"
) -> tuple[MPSSolver, gpu.GPUSolver]:
    """A square 2-D tank ``width`` (m) wide filled ``width`` deep, at rest, on both paths
    (the matrix's entries in ``precision``, fluid.matrix_precision)."""
    walls, kinds = tank(width, width, L0, dim=2, lattice="square")
    water = water_block(0.0, width, 0.0, width, L0, lattice="square")
    positions = np.concatenate([water, walls])
    kinds = np.concatenate([np.full(len(water), FLUID, np.int8), kinds])
    params = MPSParameters(
        dim=2, l0=L0, lattice="square", tolerance=1e-8, solver=solver,
        matrix_precision=precision,
    )  # fmt: skip
    return MPSSolver(params, positions, kinds), gpu.GPUSolver(params, positions, kinds)


@pytest.mark.parametrize("precision", ["double", "single"])
def test_the_two_level_preconditioner_saves_iterations(monkeypatch, precision: str) -> None:
    """fluid.solver = "deflated" on the GPU: Jacobi plus the coarse correction on aggregates
    (blocks of search cells, E^-1 dense). On a tank of 900 water particles with 72 aggregates
    (one per ten particles here: the run's default is one per 200, too few in so small a tank)
    the CG takes at most 60 % of the iterations of plain CG (measured: 22 against the CPU's
    51; Jacobi on the GPU took 48), and its pressure is the CPU deflated solver's to the
    tolerance's scale (both solve to 1e-8 of |b|: the pressures agree to 1e-6 of the
    largest; measured 1e-8). With the matrix's entries in single precision too (the coarse
    matrix summed from the rounded coefficients, on both paths)."""
    monkeypatch.setattr(gpu, "COARSE_PARTICLES", 10)
    plain, _ = _still_square(0.3, "cg")
    cpu, device = _still_square(0.3, "deflated", precision)
    dt = cpu.stable_dt()
    reference = plain.step(dt).iterations
    cpu.step(dt)
    stats = device.step(dt)
    assert device.coarse_aggregates > 50
    assert device._coefficient.dtype == {"double": np.float64, "single": np.float32}[precision]
    assert stats.iterations <= 0.6 * reference
    assert np.abs(device.pressure - cpu.pressure).max() <= 1e-6 * cpu.pressure.max()


def test_a_two_level_run_resumes_to_the_bit(monkeypatch) -> None:
    """The coarse space is made anew at each frame's first solve (begin_frame) and after a
    restore, so a run resumed from a frame's checkpoint solves with the E^-1 the run had; and
    two runs refresh it on the same steps (their iteration counts are the same)."""
    monkeypatch.setattr(gpu, "COARSE_PARTICLES", 10)
    _, first = _still_square(0.1, "deflated")
    dt = first.stable_dt()
    first.begin_frame()
    first.step(dt)
    checkpoint = first.state_arrays()
    resumed = gpu.GPUSolver(first.params, checkpoint["position"], first.kind)
    resumed.restore(checkpoint)
    first.begin_frame()  # the next frame
    for solver in (first, resumed):
        solver.step(dt)
    assert first.coarse_aggregates > 1
    for name, value in first.state_arrays().items():
        np.testing.assert_array_equal(resumed.state_arrays()[name], value, err_msg=name)


def _lists_match_the_cpu_search(
    device: gpu.GPUSolver, positions: np.ndarray, kinds: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Every row of the GPU's lists (all particles alive, at ``positions``) holds the CPU cell
    search's neighbours at the CPU's distances. Returns the GPU's (count, index)."""
    from jellysim.fluid.neighbours import search_neighbours

    count = device._list_count.copy_to_host()
    index = device._index.copy_to_host()
    distance = device._distance.copy_to_host()
    rows = kinds != DUMMY
    alive = np.ones(len(kinds), dtype=bool)
    start, cpu_index, cpu_distance = search_neighbours(
        positions, alive, rows, device.search_radius, np.empty(0, np.int32), np.empty(0)
    )
    for i in range(len(kinds)):  # a dummy's row is empty on both
        row = slice(start[i], start[i + 1])
        expected = dict(zip(cpu_index[row], cpu_distance[row], strict=True))
        got = dict(zip(index[: count[i], i], distance[: count[i], i], strict=True))
        assert got.keys() == expected.keys(), i
        for j, r in got.items():
            assert r == pytest.approx(expected[j], rel=1e-15)
    return count, index


def test_neighbour_lists_match_the_cell_search_and_grow() -> None:
    """Each row of the GPU's fixed-width list holds the CPU cell search's neighbours, in
    particle order within a cell; a width too small is grown and the search repeated. A wall
    particle far from the tank widens the cell grid to several tiles of BLOCK cells, so the
    cells' starts carry from tile to tile (the fused search's tile stages)."""
    positions, kinds = _particles(2, "square")
    positions = np.concatenate([positions, [[1.0, 1.0]]])
    kinds = np.concatenate([kinds, [WALL]]).astype(np.int8)
    params = MPSParameters(dim=2, l0=L0)
    device = gpu.GPUSolver(params, positions, kinds)
    device._allocate_lists(4)  # far too narrow: the search must grow it
    device._search(device._d_position, device._rows_all, device._wet)
    assert device.width > 4
    cell = device._cell.copy_to_host()
    assert device._tile_sums.shape[0] >= 5  # tiles of BLOCK cells
    per_cell = np.bincount(cell, minlength=device._cells)
    start = device._start.copy_to_host()
    np.testing.assert_array_equal(start, np.concatenate([[0], np.cumsum(per_cell)]))
    member = device._member.copy_to_host()
    for c in np.flatnonzero(per_cell):
        within = member[start[c] : start[c + 1]]
        np.testing.assert_array_equal(within, np.flatnonzero(cell == c))
    count, index = _lists_match_the_cpu_search(device, positions, kinds)
    cell = device._cell.copy_to_host()
    for i in range(len(kinds)):
        # in the order of the cells around i (increasing cell number), by index within a cell
        order = [(cell[j], j) for j in index[: count[i], i]]
        assert order == sorted(order), i


def test_the_3d_search_finds_every_pair_also_beyond_the_cell_grid() -> None:
    """In 3-D, with particles moved after the solver was built past its cell grid (the
    initial box and a search radius around it) above, beside and below it, where they count
    in the nearest edge cell: every row holds the CPU cell search's neighbours at the CPU's
    distances (the CPU's grid is the live particles' box, so it clamps nothing)."""
    positions, kinds = _particles(3, "fcc")
    params = MPSParameters(dim=3, l0=L0, lattice="fcc")
    device = gpu.GPUSolver(params, positions, kinds)
    radius = device.search_radius
    fluid = np.flatnonzero(kinds == FLUID)
    moved = positions.copy()
    top, side, low = positions.max(axis=0)[2], positions.max(axis=0)[0], positions.min(axis=0)[2]
    # a pair 3 radii above the grid's top, 0.6 radius apart; one particle 2.5 radii past its
    # side; a pair 1.5 radii below its floor, 0.9 radius apart
    moved[fluid[0]] = [0.01, 0.01, top + 4.0 * radius]
    moved[fluid[1]] = moved[fluid[0]] + [0.6 * radius, 0.0, 0.0]
    moved[fluid[2]] = [side + 3.5 * radius, 0.02, 0.02]
    moved[fluid[3]] = [0.015, 0.02, low - 2.5 * radius]
    moved[fluid[4]] = moved[fluid[3]] + [0.0, 0.5 * radius, -0.7 * radius]
    device._d_position.copy_to_device(moved)
    device._search(device._d_position, device._rows_all, device._wet)
    count, index = _lists_match_the_cpu_search(device, moved, kinds)
    assert set(index[: count[fluid[0]], fluid[0]]) == {fluid[1]}
    assert set(index[: count[fluid[3]], fluid[3]]) == {fluid[4]}
    assert count[fluid[2]] == 0


def test_gpu_solver_fails_as_the_cpu_one_does() -> None:
    """A pressure solve that cannot reach its tolerance raises FluidDiverged."""
    from jellysim.fluid.solvers import FluidDiverged

    positions, kinds = _particles(2, "square")
    params = MPSParameters(dim=2, l0=L0, max_iterations=2, tolerance=1e-14)
    device = gpu.GPUSolver(params, positions, kinds)
    with pytest.raises(FluidDiverged, match="relative residual"):
        device.step(device.stable_dt())


def test_the_solve_reports_a_non_finite_source_and_skips_a_zero_one() -> None:
    """A NaN in b is a FluidDiverged (a non-finite residual, as the CPU's CG gives); b = 0
    with a non-zero warm start is solved by x = 0 in no iteration (the CPU's answer)."""
    from jellysim.fluid.solvers import FluidDiverged

    positions, kinds = _particles(2, "square")
    device = gpu.GPUSolver(
        MPSParameters(dim=2, l0=L0, source="mixed", gradient="corrected"), positions, kinds
    )
    device.step(device.stable_dt())  # rows, source and a warm start in place
    k = device.k
    k["fill"][gpu._grid(device.n), gpu.BLOCK](device._b, np.nan)
    with pytest.raises(FluidDiverged):
        device._solve()
    k["fill"][gpu._grid(device.n), gpu.BLOCK](device._b, 0.0)
    k["fill"][gpu._grid(device.n), gpu.BLOCK](device._x, 5.0)
    assert device._solve() == (0, 0.0)
    assert not device._x.copy_to_host().any()
    with pytest.raises(ValueError, match="external_force"):
        device.step(1e-4, np.zeros((1, 2)))


def test_no_gpu_is_an_input_error(tmp_path) -> None:
    """Without a GPU (and the simulator off), --device cuda is one line, exit 2, nothing
    written."""
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    out = tmp_path / "run"
    done = subprocess.run(
        [sys.executable, "-m", "jellysim", "run", "hydrostatic-2d", "--device", "cuda",
         "--out", str(out), "--quiet"],
        capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip
    if done.returncode == 0:
        pytest.skip("this machine has a GPU")
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "fluid.device = 'cuda'" in lines[0], done.stderr
    assert "pip install jellysim[cuda]" in lines[0]
    assert not out.exists()


def _bell_pair(options: dict[str, object]):
    """The tests' coarse moon jelly (tests/scenes.py SWIM) with ``options``, its water on the CPU
    and on the GPU from one state: the bell's particles moved by up to a few hundredths of l0
    and stirred, so that every spring is stretched or compressed and K v is not zero."""
    import scenes

    from jellysim import load_scene
    from jellysim.coupling.bell_in_fluid import BellInFluid

    overrides = {**scenes.SWIM, "duration": 0.2, **options}
    cpu = BellInFluid(load_scene("moon-jelly", overrides))
    on_gpu = BellInFluid(load_scene("moon-jelly", {**overrides, "fluid.device": "cuda"}))
    assert isinstance(on_gpu.solver, gpu.GPUSolver) and on_gpu.on_gpu
    rows = cpu.bell_rows
    state = cpu.solver.state_arrays()
    rng = np.random.default_rng(7)
    state["velocity"][rows] = rng.normal(0.0, 0.05, (rows.stop - rows.start, 3))
    state["position"][rows] += rng.normal(0.0, 0.01, (rows.stop - rows.start, 3))
    cpu.solver.restore(state)
    on_gpu.solver.restore(state)
    return cpu, on_gpu


def test_the_soft_bells_explicit_springs_on_the_gpu_are_the_cpus() -> None:
    """Explicit springs (Eq. B8) with a tapered muscle mid-contraction (Eq. B9) and the
    tentacles' reaction (Eq. S2) on the water and the bell: the GPU's force density is the CPU's
    to the bit (the same operations in the same order; the simulator contracts no FMAs), on the
    bell's rows and the water's, and the frame's record of the bell is the same. With the
    reaction gone, the water's rows are free again."""
    cpu, on_gpu = _bell_pair({"bell.spring_integration": "explicit", "bell.muscle_taper": 0.5})
    reaction = np.random.default_rng(3).normal(0.0, 50.0, cpu.solver.position.shape)
    cpu.reaction = reaction.copy()  # flow.two_way's array, as take_reaction leaves it
    on_gpu.reaction = np.zeros_like(reaction)
    on_gpu.set_reaction(reaction)
    time = 0.3  # the contraction's middle: 0 < a < 1
    assert 0.0 < cpu.body.activation(time) < 1.0
    expected = cpu._spring_force_density(time, 1e-3).copy()
    got = on_gpu._spring_force_density(time, 1e-3).copy_to_host()
    rows = cpu.bell_rows
    assert np.abs(expected[rows] - reaction[rows]).max() > 1e3  # N/m3: the springs pull
    np.testing.assert_array_equal(got, expected)
    on_gpu._gpu_springs.set_reaction(None)
    cpu.reaction = None
    free = on_gpu._spring_force_density(time, 1e-3).copy_to_host()
    np.testing.assert_array_equal(free[rows], cpu._spring_force_density(time, 1e-3)[rows])
    assert not np.any(free[: rows.start]) and not np.any(free[rows.stop :])
    cpu.record(0)
    on_gpu.record(0)
    np.testing.assert_array_equal(on_gpu.position, cpu.position)
    np.testing.assert_array_equal(on_gpu.velocity, cpu.velocity)
    assert on_gpu.solver.constants == cpu.solver.constants


def test_the_soft_bells_implicit_springs_on_the_gpu_match_the_cpus() -> None:
    """Linearised backward Euler (spring_integration = "implicit", the presets'): the GPU
    assembles ``(m I - dt^2 K) dv = dt (F + dt K v)`` in rows and solves it with the pressure's
    Jacobi CG; the CPU applies K matrix-free in an unpreconditioned CG. Both stop at a relative
    residual of 1e-10 (IMPLICIT_TOLERANCE), and the matrix is m I plus a positive semi-definite
    part, so each solution is within 1e-10 |b| / m of the exact one: the force densities agree
    to 1e-9 of the largest (measured: 7e-12 at dt = 0.01 s). The water's rows stay free."""
    cpu, on_gpu = _bell_pair({"bell.spring_integration": "implicit"})
    expected = cpu._spring_force_density(0.3, 1e-2).copy()
    got = on_gpu._spring_force_density(0.3, 1e-2).copy_to_host()
    rows = cpu.bell_rows
    scale = np.abs(expected[rows]).max()
    assert scale > 1e3  # N/m3
    np.testing.assert_allclose(got, expected, rtol=0.0, atol=1e-9 * scale)
    assert not np.any(got[: rows.start]) and not np.any(got[rows.stop :])


def test_the_gpus_implicit_springs_fail_as_the_cpus() -> None:
    """A bell particle with a non-finite velocity: the GPU's implicit solve stops and says so
    as the CPU's does (SimulationUnstable), instead of giving the water NaN forces."""
    from jellysim.errors import SimulationUnstable

    cpu, on_gpu = _bell_pair({"bell.spring_integration": "implicit"})
    state = cpu.solver.state_arrays()
    state["velocity"][cpu.bell_rows.start + 5] = np.nan
    for coupling in (cpu, on_gpu):
        coupling.solver.restore(state)
        with pytest.raises(SimulationUnstable, match="implicit spring solve"):
            coupling._spring_force_density(0.3, 1e-3)


def test_a_run_resumes_on_the_other_device() -> None:
    """Checkpoints and results record fluid.device, which is not part of what is simulated:
    the same scene on the other device is the same scene for --resume."""
    from jellysim import load_scene, scene_to_toml
    from jellysim.config.load import same_scene

    on_gpu = scene_to_toml(load_scene("hydrostatic-2d", {"fluid.device": "cuda"}))
    on_cpu = scene_to_toml(load_scene("hydrostatic-2d"))
    assert on_gpu != on_cpu and same_scene(on_gpu, on_cpu)
    other = scene_to_toml(load_scene("hydrostatic-2d", {"fluid.courant": 0.1}))
    assert not same_scene(on_gpu, other)


def test_escaped_particles_are_counted_on_the_gpu_as_on_the_cpu() -> None:
    """A particle thrown out of the domain dies on both devices; the GPU counts the dead on the
    device (no download of the alive flags a step), and a restored state brings its count."""
    cpu, device, kinds, _ = _pair("standard-2d")
    dt = cpu.stable_dt()  # of the water at rest: the thrown particle leaves in one step
    state = cpu.state_arrays()
    thrown = int(np.flatnonzero(cpu.kind == FLUID)[0])
    state["velocity"][thrown] = [-1.0e4, 0.0]  # beyond the domain (twice the tank) in one step
    cpu.restore(state)
    device.restore(state)
    on_cpu, on_gpu = cpu.step(dt), device.step(dt)
    assert on_cpu.dead == on_gpu.dead == 1
    np.testing.assert_array_equal(device.alive, cpu.alive)
    assert not device.alive[thrown]
    resumed = gpu.GPUSolver(device.params, state["position"], kinds)
    resumed.restore(device.state_arrays())
    assert resumed.step(dt).dead == device.step(dt).dead == 1
