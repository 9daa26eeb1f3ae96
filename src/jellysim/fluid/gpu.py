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

A step is six cooperative launches (each kernel's blocks all resident, the grid meeting at
barriers between its stages, :mod:`jellysim.fluid.gpu_kernels`): the neighbour search at r^k,
the explicit phase, the search at r*, the Poisson system's assembly, the solve and the
correction; and five small reads: each search's widest row, the solve's residual, and the
step's counters with the new state's extent (the next step's dt). A search repeated with wider
lists, a new coarse space, and the first dt after a start or a restore add theirs. A launch
costs tens of microseconds on the host, more than most stages' work at 57,000 particles; the
step was about forty launches until 2026-11-28, with the same arithmetic but for the coarse
correction's sums (docs/decisions.md).

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

from jellysim.fluid.geometry import DUMMY
from jellysim.fluid.mps import (
    MATRIX_PRECISIONS,
    MPSParameters,
    PhaseTimer,
    StepStats,
    lattice_reference,
    solver_setup,
    step_limits,
)
from jellysim.fluid.neighbours import CELLS_PER_RADIUS
from jellysim.fluid.solvers import FluidDiverged

log = logging.getLogger(__name__)

# numba-cuda 0.30 registers an overload of np.row_stack when it compiles its first kernel, and
# NumPy 2.5 removed that alias of np.vstack: without it no kernel compiles (docs/decisions.md).
if not hasattr(np, "row_stack"):
    np.row_stack = np.vstack  # type: ignore[attr-defined]

try:  # Numba's CUDA support (the kernels, in gpu_kernels, import it themselves)
    from numba import cuda
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
# of k x k (x k) search cells, k CELLS_PER_RADIUS times the whole search radii nearest to
# ``coarse_cell`` l0, grown by CELLS_PER_RADIUS while there are more than one per
# COARSE_PARTICLES particles and COARSE_LARGEST in all (E^-1 is dense on the GPU,
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
# The coarse correction's team (:func:`coarse_team`) in Numba's CUDA simulator.
COARSE_TEAM_SIMULATED = 4

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
    """The CUDA kernels by name (:mod:`jellysim.fluid.gpu_kernels`, imported on first use; each
    compiled at its first launch with new argument types, or loaded from Numba's cache)."""
    global _KERNELS
    if _KERNELS is None:
        from jellysim.fluid import gpu_kernels

        _KERNELS = gpu_kernels.KERNELS
    return _KERNELS


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
        # The cell grid, cells radius / CELLS_PER_RADIUS wide (the CPU search's), over the
        # particles' initial box and a search radius around it: a particle beyond it counts in
        # the nearest cell on its edge (clamping keeps two particles within the radius within
        # CELLS_PER_RADIUS cells of each other, so no pair is missed; the domain around the
        # tank, where splashes die, needs no cells of its own).
        self._cell_size = cell = self.search_radius / CELLS_PER_RADIUS
        low = positions.min(axis=0) - self.search_radius
        high = positions.max(axis=0) + self.search_radius
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
        self._member_position = da((dim, n))  # the members' coordinates, in cell order
        self._within = da(n, dtype=np.int32)
        self._unknown = da(n, dtype=np.int8)
        self._rows_all = d((self.kind != DUMMY).astype(np.bool_))
        self._rows = da(n, dtype=np.bool_)
        self._wet = da(n + 1, dtype=np.int8)  # the last: 1 for every row (the first search)
        self._most = da(1, dtype=np.int64)
        # the step's counters: its free-surface particles and the dead so far (SURFACE, DEAD)
        self._counts = cuda.to_device(np.zeros(2, dtype=np.int64))
        # the PPE's rows and the CG's vectors, over all particles (0 off the unknowns)
        self._diagonal, self._inverse_diagonal = da(n), da(n)
        self._b, self._x, self._r, self._z, self._q = da(n), da(n), da(n), da(n), da(n)
        self._d0 = da(n)
        self._lowest = da(n)
        self._partial = da((2, _grid(n), 3))  # the CG's block sums, two slots
        self._solve_out = da(4)
        self._blocks: dict[str, int] = {}  # each cooperative kernel's blocks, at its first launch
        self._extent = da(4)
        self._extent_host: np.ndarray | None = None  # the state's, made by the step that left it
        self._allocate_lists(self.width)
        self._host: dict[str, np.ndarray] = {}
        # the coarse space (fluid.solver = "deflated"): none until the first solve makes it
        self.two_level = p.solver == "deflated"
        # aggregates of whole radius-wide cells (blocks of CELLS_PER_RADIUS^D search cells),
        # as before the search's cells were halved: the same aggregates, the same iterations
        whole = max(1, round(p.coarse_cell * l0 / self.search_radius))
        self._coarse_base = CELLS_PER_RADIUS * whole
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
        # the PPE's off-diagonal entries, in single precision with fluid.matrix_precision
        real = MATRIX_PRECISIONS[self.params.matrix_precision]
        self._coefficient = da((width, self.n), dtype=real)
        self._list_count = da(self.n, dtype=np.int32)

    def _search(self, position: Any, rows: Any, every: Any) -> None:
        """The neighbour lists at ``position`` for the particles of ``rows`` (all live walls
        and fluid particles where ``every[-1]`` is 1), in one cooperative launch; searched
        again, wider, while a row does not fit."""
        self.searches += 1
        while True:
            self._launch(
                "neighbour_search", max(self.n, self._cells), position, self._d_alive,
                self._d_lower, 1.0 / self._cell_size, self._d_shape, rows, every,
                self._d_kind, self.search_radius, self._cell, self._count, self._cursor,
                self._tile_sums, self._tile_offsets, self._start, self._member,
                self._member_position, self._index, self._distance, self._list_count,
                self._most,
            )  # fmt: skip
            most = int(self._most.copy_to_host()[0])
            if most <= self.width:
                return
            self._allocate_lists(int(most * 1.25) + 8)

    def _launch(self, name: str, rows: int, *args: Any) -> None:
        """A cooperative launch of kernel ``name`` over ``rows`` rows: a block per ``BLOCK``
        rows, or as many as the GPU holds at once (found at its first launch)."""
        kernel = self.k[name]
        blocks = self._blocks.get(name)
        if blocks is None:
            blocks = self._blocks[name] = cooperative_blocks(kernel, args, _grid(rows))
        kernel[blocks, BLOCK](*args)

    # --------------------------------------------------------------------------------- step

    def begin_frame(self) -> None:
        """The coarse space (fluid.solver = "deflated") is made anew at a frame's first solve,
        as after :meth:`restore`: a run resumed from a frame's checkpoint then solves with the
        E^-1 the run itself had, to the bit."""
        self._coarse_age = COARSE_REFRESH

    def stable_dt(self, external_acceleration: float = 0.0) -> float:
        """As :meth:`MPSSolver.stable_dt`, the maxima taken on the GPU."""
        p = self.params
        if self._extent_host is None:  # no step has left this state (a start, a restore)
            self._extent.copy_to_device(np.array([0.0, -np.inf, -np.inf, 0.0]))
            self.k["extent"][_grid(self.n), BLOCK](
                self._d_position, self._d_velocity, self._d_kind, self._d_alive, self._d_axis,
                self._extent,
            )  # fmt: skip
            self._extent_host = self._extent.copy_to_host()
        speed2, high, minus_low, fluid = self._extent_host
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
        n = self.n
        if external_force is not None and external_force.shape != (n, p.dim):
            # the kernel reads row i of it, unchecked
            raise ValueError(f"external_force must be ({n}, {p.dim}), not {external_force.shape}")
        self._host.clear()
        self._extent_host = None  # the state moves
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
        with timer("explicit"):
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
            self._launch(
                "explicit_phase", n + 1, self._d_position, self._d_velocity, self._d_kind,
                self._d_alive, self._index, self._distance, self._list_count, re_nd, mixed,
                self._d_start_density, self._within, re_lap,
                p.kinematic_viscosity * 2.0 * dim / (ref_lap.lambda_ * ref_lap.n0),
                self._d_gravity, external, has_external, p.density, dt,
                p.collision_distance * p.l0, 0.5 * (1.0 + p.collision_restitution),
                self._start_position, self._scratch_position, self._scratch_velocity,
                self._wet, self.search_radius - re_nd, self._rows,
            )  # fmt: skip
            sync()
        with timer("neighbours"):
            # rows at r*: the fluid and the walls it reached at r^k (MPSSolver._wet)
            self._search(self._d_position, self._rows, self._wet)
        with timer("assembly"):
            threshold = p.beta * ref_nd.n0
            self._launch(
                "assembly_phase", n, self._d_position, self._d_velocity, self._d_kind,
                self._d_alive, self._index, self._distance, self._list_count, re_nd,
                self._d_density, self._within, self._d_start_density, threshold,
                p.surface == "neighbour-count", p.surface_neighbour_threshold * ref_nd.count,
                p.surface == "either-density" and mixed, self._unknown, self._counts, re_lap,
                2.0 * dim / (ref_lap.lambda_ * ref_lap.n0), p.density * p.compressibility / dt**2,
                re_grad, dim / ref_grad.n0, mixed,
                p.density / dt if mixed else p.density / dt**2,
                p.mixed_relaxation * p.density / dt**2, ref_nd.n0, self._d_pressure,
                self._coefficient, self._diagonal, self._inverse_diagonal, self._b, self._x,
                p.matrix_precision == "single",
            )  # fmt: skip
            sync()
        with timer("solve"):
            stats.iterations, stats.residual = self._solve()
        with timer("correction"):
            conservative = p.gradient == "conservative"
            self._launch(
                "correction_phase", n, self._d_position, self._d_velocity, self._d_pressure,
                self._d_kind, self._d_alive, self._index, self._distance, self._list_count,
                self._unknown, self._x, re_grad, re_lap, ref_grad.n0,
                -dt * dim / (ref_grad.n0 * p.density), dt, p.gradient == "corrected",
                conservative, self._lowest, p.surface_repulsion, self._scratch_position,
                self._scratch_velocity, self._d_domain_min, self._d_domain_max, self._counts,
                self._d_axis, self._extent,
            )  # fmt: skip
            self.time += dt
            # the step's one read of counters: the free surface's and the dead's counts, and
            # the new state's extent for the next step's dt (stable_dt)
            surface, dead = self._counts.copy_to_host()
            stats.surface, stats.dead = int(surface), int(dead)
            self._extent_host = self._extent.copy_to_host()
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
        self._launch("conjugate_gradient", self.n, *args)
        iterations, rr, bb, not_finite = self._solve_out.copy_to_host()
        if self.two_level:
            self._coarse_age += 1
            if self._coarse_age == 1:
                self._coarse_baseline = int(iterations)
            elif iterations > COARSE_STALE * self._coarse_baseline + 2:
                self._coarse_age = COARSE_REFRESH  # stale: a new E^-1 for the next solve
        # a non-finite b (NaN or inf) gives a non-finite residual, as on the CPU
        residual = 0.0 if bb == 0.0 else math.sqrt(rr / bb)
        if not (residual <= p.tolerance) or not_finite:
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
            self._coarse_k += CELLS_PER_RADIUS
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
            d_to_coarse, d_blocks, d(np.ascontiguousarray(inverse)), da(m), da(m),
            coarse_team(),
        )  # fmt: skip
        self.coarse_aggregates = m

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
        self._counts.copy_to_device(np.array([0, np.count_nonzero(~values["alive"])], np.int64))
        self.kind[:] = arrays["kind"]
        self._d_kind.copy_to_device(self.kind)
        self._rows_all.copy_to_device((self.kind != DUMMY).astype(np.bool_))
        self.time = float(arrays["time"])
        self._host.clear()
        self._extent_host = None
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
            coarse_team(),
        )  # fmt: skip
    return _NO_COARSE


def coarse_team() -> int:
    """The threads that share an aggregate's sums in the coarse correction: a block on a GPU
    (the shortest chains of loads, a tree of 7 levels); COARSE_TEAM_SIMULATED in the simulator,
    where each level of the tree is a barrier of 128 Python threads (a team serves BLOCK / team
    aggregates at once). Another team sums in another order: other round-off, as on another
    card."""
    return COARSE_TEAM_SIMULATED if simulated() else BLOCK


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
        log.warning("a cooperative grid: %s; using %d blocks", error, most)
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
