"""The MPS solver: parameters, state and the semi-implicit step [Koshizuka & Oka 1996].

References
----------
- Koshizuka, S. & Oka, Y. (1996). Moving-particle semi-implicit method for fragmentation of
  incompressible fluid. Nucl. Sci. Eng. 123, 421-434. The standard scheme (default).
- Tanaka, M. & Masunaga, T. (2010). Stabilization and smoothing of pressure in MPS method by
  Quasi-Compressibility. J. Comput. Phys. 229, 4279-4290. Mixed source term
  (``source="mixed"``) and the neighbour-count surface criterion (``surface="neighbour-count"``).
- Khayyer, A. & Gotoh, H. (2011). Enhancement of stability and accuracy of the moving particle
  semi-implicit method. J. Comput. Phys. 230, 3093-3118. The corrected pressure gradient
  (``gradient="corrected"``, Eq. F10a).
- Khayyer, A. & Gotoh, H. (2008). Development of CMPS method for accurate water-surface
  tracking in breaking waves. Coast. Eng. J. 50, 179-207. The pair-wise antisymmetric,
  momentum-conserving gradient (``gradient="conservative"``, Eq. F10c).
- Ikeda, H., Koshizuka, S., Oka, Y. et al. (2001). Numerical analysis of jet injection behavior
  for fuel-coolant interaction using particle method. J. Nucl. Sci. Technol. 38, 174-182. The
  compressibility term of the pressure Poisson equation.

Equation numbers (F1)-(F13) refer to docs/theory/fluid.md.
"""

from __future__ import annotations

import math
import time as _time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from jellysim.fluid import kernels
from jellysim.fluid.geometry import DUMMY, FLUID, ROW_HEIGHT, WALL, check_lattice
from jellysim.fluid.linalg import Matrix
from jellysim.fluid.neighbours import (
    Neighbours,
    filter_with_near,
    largest_displacement,
    listed,
    near_neighbours,
    search_neighbours,
    search_with_near,
    wave_chunks,
)
from jellysim.fluid.poisson import assemble_poisson, number_unknowns
from jellysim.fluid.probes import weighted_sums
from jellysim.fluid.solvers import PRESSURE_SOLVERS, CoarseSpace, FluidDiverged, solve

SOURCES = ("standard", "mixed")
SURFACES = ("standard", "neighbour-count", "either-density")
GRADIENTS = ("standard", "corrected", "conservative")
# fluid.matrix_precision: the type in which the PPE's off-diagonal entries are stored
MATRIX_PRECISIONS = {"double": np.float64, "single": np.float32}
# beta of the surface criterion n < beta n0 when none is given, per lattice. 0.97 is Koshizuka &
# Oka's for the square lattice, whose second row under a flat surface has n = 0.992 n0 (it misses
# the neighbour two spacings up). On the hexagonal lattice the second row misses three (one at
# sqrt(3) l0, two at 2 l0): n = 0.962 n0, under 0.97, so that row would flicker between the
# surface and the interior; 0.93 leaves it 3 % of margin, the surface row (0.64 n0) far below.
# On the face-centred cubic lattice the second layer under a flat (111) surface misses six
# neighbours (at sqrt(8/3) and 2 l0): n = 0.964 n0; the surface layer has 0.69 n0. Same 0.93.
SURFACE_THRESHOLD = {"square": 0.97, "hexagonal": 0.93, "fcc": 0.93}

# PPEs with at least this many unknowns are ordered in two uncoupled blocks and a separator, so
# that IC(0) and its triangular solves run on two threads (number_unknowns); smaller
# ones keep one block: they are fast anyway, and the ordering can cost an iteration.
TWO_BLOCK_ROWS = 16384

# The collisions read the list at the near radius when the collision distance lies this many l0
# inside it: the list is drawn at r^k, the collisions tested at r*, and a particle moves far less
# than l0 in the explicit stage (the Courant number keeps it to a fraction of l0).
COLLISION_MARGIN = 1.0


@dataclass(frozen=True)
class MPSParameters:
    """What the user sets for an MPS fluid (SI units; radii in units of l0).

    Defaults are the standard scheme of Koshizuka & Oka (1996): r_e = 2.1 l0 for the number
    density and the gradient, 4.0 l0 for the Laplacian in 2-D. In 3-D the Laplacian radius
    defaults to 3.1 l0 (the customary 3-D choice; 4.0 l0 would give ~270 neighbours a particle).

    - ``source``: "standard", PPE source ``-(rho/dt^2)(n* - n0)/n0`` [Koshizuka & Oka 1996];
      "mixed", ``(rho/dt) div u* - gamma (rho/dt^2)(n^k - n0)/n0`` with gamma =
      ``mixed_relaxation`` [Tanaka & Masunaga 2010].
    - ``surface``: "standard", free surface where ``n* < beta n0``; "neighbour-count", also where
      fewer than ``surface_neighbour_threshold`` N0 neighbours lie within r_e (N0 the lattice
      count) [Tanaka & Masunaga 2010]. Not yet sound: in the 2-D hydrostatic tank it lets a
      surface particle be kicked to ~7 m/s after 0.14 s; use "standard". "either-density"
      (this project's, docs/theory/fluid.md F7b; mixed source only): fluid and wall particles
      are on the free surface where ``n* < beta n0`` or ``n^k < beta n0``, so that a surface
      particle pushed into a neighbour during the explicit stage (a collision at a splash) does
      not become, for that step only, an interior particle whose neighbours are almost all
      Dirichlet p = 0, with a pressure spike from its velocity-divergence source.
    - ``gradient``: "standard", the minimum-pressure gradient of Eq. (F10) [Koshizuka & Oka
      1996]; "corrected", the same multiplied by the inverse moment matrix of the particle's
      neighbourhood, Eq. (F10a) [Khayyer & Gotoh 2011]: a particle at a flat free surface
      carries its full weight (the standard gradient balances half), and one-sided
      neighbourhoods at walls are compensated but for the minimum-pressure term. The mixed
      source needs it: with the standard gradient the mixed source's dam break blows up
      (docs/fluid.md). "conservative": the pair-wise antisymmetric gradient of Eq. (F10c)
      [Khayyer & Gotoh 2008], ``(p_i + p_j) - (p_min,i + p_min,j)`` in place of
      ``p_j - p_min,i``: two fluid particles push each other equally and oppositely, so the
      pressure conserves the water's momentum (with walls, but for what they give). Not with
      ``surface_repulsion``, which pushes one particle of a pair only.
    - ``collision_distance`` (l0) and ``collision_restitution``: the collision model, Eq. (F6).
      The customary 0.5 l0 lets a surge's tip particle sink to about 0.65 l0 above a floor
      particle, whose PPE row (its neighbours nearly all on the free surface) then throws it off
      the floor; 0.8 l0 stops that without slowing the water behind (docs/fluid.md).
    - ``surface_repulsion``: free-surface fluid particles are pushed apart along the surface by
      the largest pressure among their fluid neighbours, Eq. (F10b) (this project's;
      docs/theory/fluid.md): with a Dirichlet p = 0 the minimum-pressure gradient repels nobody
      at the surface, and still water's top row slides along it without this.
    - ``solver``: "iccg" (IC(0)-preconditioned CG), "cg" (plain CG, for comparison) or
      "deflated" (CG with Jacobi and a coarse problem on aggregates ``coarse_cell`` l0 wide,
      :mod:`jellysim.fluid.deflation`); ``tolerance`` is the relative residual
      ``|b - A p| / |b|``.
    - ``matrix_precision``: "double", or "single": the off-diagonal entries of A are rounded to
      single precision where they are stored, and the diagonal, kept in double, sums the rounded
      entries, so that each row's excess over its unknown neighbours (its free-surface
      neighbours and the compressibility) is the double one. A stays exactly symmetric and
      positive definite; a product with A reads 8 bytes an entry instead of 12
      (:func:`jellysim.fluid.poisson.assemble_poisson`, docs/decisions.md).
    - ``neighbour_skin`` (l0): 0, a cell search for each neighbour list (two a step); above 0,
      one search with the radius widened by the skin serves as a Verlet list, cut to the radius
      at each use and searched again only when some particle has moved half the skin since
      (:meth:`MPSSolver.neighbours`). The lists then keep the order of the wider search, so
      sums run in another order than with 0: the same physics, other round-off.
    - ``compressibility`` alpha (1/Pa): adds ``(rho alpha / dt^2) p`` to the PPE's left side, the
      fluid's slight compressibility [Ikeda et al. 2001]. It keeps the matrix non-singular when no
      particle is on the free surface; water's 0.45e-9 1/Pa makes it a regulariser only.
    - ``free_fall_floor``: whether the CFL speed is floored at a free fall over the water's
      height (:meth:`MPSSolver.stable_dt`).
    - ``acceleration_number`` kappa: the acceleration limit ``dt <= kappa sqrt(l0 / a)``, i.e. a
      particle at rest moves ``kappa^2 l0 / 2`` in a step; None: ``sqrt(courant)``.
    - ``lattice``: the initial arrangement whose neighbourhood defines n0 and lambda (Eq.
      F2-F3): "square" (cubic in 3-D), "hexagonal" (2-D only) or "fcc" (face-centred cubic,
      3-D only; :mod:`jellysim.fluid.geometry`). The particles must be built on the same
      lattice.
    - ``domain_min``/``domain_max`` (m): particles leaving the box die (``alive`` False). None:
      the initial particles' bounding box widened by its own size on every side.
    """

    dim: int
    l0: float
    density: float = 1000.0
    kinematic_viscosity: float = 1e-6
    gravity: tuple[float, ...] | None = None  # m/s2; None: 9.81 down the last axis
    re_number_density: float = 2.1
    re_gradient: float = 2.1
    re_laplacian: float | None = None  # None: 4.0 in 2-D, 3.1 in 3-D
    surface_threshold: float | None = None  # None: SURFACE_THRESHOLD of the lattice
    surface_neighbour_threshold: float = 0.85
    collision_distance: float = 0.5
    collision_restitution: float = 0.2
    surface_repulsion: bool = False
    source: str = "standard"
    mixed_relaxation: float = 0.01
    surface: str = "standard"
    gradient: str = "standard"
    solver: str = "iccg"
    matrix_precision: str = "double"
    coarse_cell: float = 4.0
    neighbour_skin: float = 0.0
    tolerance: float = 1e-8
    max_iterations: int = 2000
    courant: float = 0.2
    free_fall_floor: bool = True
    acceleration_number: float | None = None
    diffusion_number: float = 0.2
    compressibility: float = 0.45e-9
    lattice: str = "square"
    domain_min: tuple[float, ...] | None = None
    domain_max: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, not {self.dim}")
        for name, value, allowed in (
            ("source", self.source, SOURCES),
            ("surface", self.surface, SURFACES),
            ("gradient", self.gradient, GRADIENTS),
            ("solver", self.solver, tuple(PRESSURE_SOLVERS)),
            ("matrix_precision", self.matrix_precision, MATRIX_PRECISIONS),
        ):
            if value not in allowed:
                raise ValueError(f"{name} = {value!r}; allowed: {', '.join(allowed)}")
        check_lattice(self.lattice, self.dim)
        if self.lattice == "hexagonal" and self.surface == "neighbour-count":
            # its threshold counts the square lattice's neighbours (the second row of the
            # hexagonal one has 15 of 18, under 0.85 N0, and would always be on the surface)
            raise ValueError("surface = 'neighbour-count' needs the square lattice")
        if self.surface == "either-density" and self.source != "mixed":
            # n^k is computed (for every fluid and wall particle) by the mixed source only
            raise ValueError("surface = 'either-density' needs source = 'mixed'")
        if self.gradient == "conservative" and self.surface_repulsion:
            raise ValueError("gradient = 'conservative' cannot take surface_repulsion")
        if self.acceleration_number is not None and not self.acceleration_number > 0.0:
            raise ValueError(f"acceleration_number must be > 0, not {self.acceleration_number}")
        if self.gravity is not None and len(self.gravity) != self.dim:
            raise ValueError(f"gravity needs {self.dim} components, not {len(self.gravity)}")
        for name in ("domain_min", "domain_max"):  # kernels.commit_step reads dim of each
            bound = getattr(self, name)
            if bound is not None and len(bound) != self.dim:
                raise ValueError(f"{name} needs {self.dim} components, not {len(bound)}")

    @property
    def beta(self) -> float:
        """The surface threshold in use: ``surface_threshold``, or the lattice's default."""
        if self.surface_threshold is not None:
            return self.surface_threshold
        return SURFACE_THRESHOLD[self.lattice]

    @property
    def laplacian_radius(self) -> float:
        """r_e of the Laplacian model in units of l0."""
        if self.re_laplacian is not None:
            return self.re_laplacian
        return 4.0 if self.dim == 2 else 3.1

    @property
    def neighbour_radius(self) -> float:
        """The neighbour lists' radius in units of l0: the largest of the three r_e."""
        return max(self.re_number_density, self.re_gradient, self.laplacian_radius)

    @property
    def gravity_vector(self) -> np.ndarray:
        """Gravity (dim,) m/s2."""
        if self.gravity is None:
            g = np.zeros(self.dim)
            g[-1] = -9.81
            return g
        return np.asarray(self.gravity, dtype=np.float64)


@dataclass(frozen=True)
class LatticeReference:
    """n0 and lambda of a particle with a full neighbourhood on the perfect lattice (Eq. F2-F3).

    ``count``: neighbours within r_e. ``n0`` dimensionless, ``lambda_`` in m2.
    """

    n0: float
    lambda_: float
    count: int


def lattice_reference(dim: int, l0: float, re: float, lattice: str = "square") -> LatticeReference:
    """n0 = sum_j w(r_j), lambda = sum_j w r_j^2 / sum_j w over the lattice points r_j != 0 with
    ``|r_j| < re l0``: on the square/cubic lattice ``r_j = l0 m`` (integer m), on the hexagonal
    one (2-D) ``r_j = l0 (m_1 + m_2 / 2, m_2 sqrt(3) / 2)``, on the face-centred cubic one (3-D)
    ``r_j = l0 (m_1 + m_2 / 2 + m_3 / 2, (m_2 + m_3 / 3) sqrt(3) / 2, m_3 sqrt(2/3))``."""
    check_lattice(lattice, dim)
    # a lattice point within re l0 has integer coordinates of at most 2 re + 1 in these bases
    reach = int(math.ceil(re)) if lattice == "square" else int(math.ceil(2.0 * re)) + 1
    axis = np.arange(-reach, reach + 1)
    offsets = np.stack(np.meshgrid(*([axis] * dim), indexing="ij"), axis=-1).reshape(-1, dim)
    offsets = offsets.astype(np.float64)
    if lattice == "hexagonal":
        offsets = np.column_stack(
            [offsets[:, 0] + 0.5 * offsets[:, 1], ROW_HEIGHT["hexagonal"] * offsets[:, 1]]
        )
    elif lattice == "fcc":
        m1, m2, m3 = offsets.T
        offsets = np.column_stack(
            [
                m1 + 0.5 * (m2 + m3),
                ROW_HEIGHT["hexagonal"] * (m2 + m3 / 3.0),
                ROW_HEIGHT["fcc"] * m3,
            ]
        )
    norm = np.sqrt((offsets**2).sum(axis=1))  # in l0
    # points on the sphere r = re (4 l0 on both lattices) are outside, whatever the round-off
    r = norm[(norm > 0) & (norm < re - 1e-9)] * l0
    w = re * l0 / r - 1.0
    return LatticeReference(float(w.sum()), float((w * r * r).sum() / w.sum()), int(r.size))


def step_limits(
    params: MPSParameters,
    speed: float | None,
    height: float | None,
    external_acceleration: float = 0.0,
) -> dict[str, float]:
    """The stability limits of the MPS step (s) by name, for fluid particles whose largest speed
    is ``speed`` (m/s) and whose extent along gravity plus l0 is ``height`` (m); both None when
    there is no live fluid particle (no Courant limit then):

    - "Courant": ``courant l0 / u``, u = ``speed`` floored (``free_fall_floor``) at
      ``sqrt(2 a H)`` with a = |g| + ``external_acceleration`` (m/s2, the largest external
      force over density) and H = ``height``: the speed of a free fall over the fluid's height,
      for water that can fall (a dam break); a filled tank, where nothing falls, needs no floor;
    - "acceleration": ``kappa sqrt(l0 / a)`` with kappa = ``acceleration_number``, by default
      ``sqrt(courant)``: the step in which a particle at rest moves courant l0 / 2;
    - "viscosity": ``diffusion_number l0^2 / nu``.

    :meth:`MPSSolver.stable_dt` takes the least; a run's estimate (``jellysim.simulation.
    estimate``) reads them before any particle exists.
    """
    p = params
    a = float(np.linalg.norm(p.gravity_vector)) + external_acceleration
    limits: dict[str, float] = {}
    if speed is not None and height is not None:
        if p.free_fall_floor:
            speed = max(speed, math.sqrt(2.0 * a * height))
        if speed > 0.0:
            limits["Courant"] = p.courant * p.l0 / speed
    if a > 0.0:
        if p.acceleration_number is None:
            limits["acceleration"] = math.sqrt(p.courant * p.l0 / a)
        else:
            limits["acceleration"] = p.acceleration_number * math.sqrt(p.l0 / a)
    if p.kinematic_viscosity > 0.0:
        limits["viscosity"] = p.diffusion_number * p.l0**2 / p.kinematic_viscosity
    return limits


class PoissonSystem(NamedTuple):
    """``A p = b`` over the unknown particles (``unknown`` (N,) bool): A in 1/m2, b (n,) Pa/m2,
    row r standing for particle ``particles[r]`` ((n,) int64; rows are in the two-block order
    of :class:`Matrix`); ``surface`` the number of free-surface particles;
    ``neighbours`` the list at the positions it was built on, ``near`` its entries within
    :attr:`MPSSolver.near_radius`."""

    matrix: Matrix
    rhs: np.ndarray
    unknown: np.ndarray
    particles: np.ndarray
    surface: int
    neighbours: Neighbours
    near: Neighbours  # its entries within the near radius (MPSSolver.near_radius)


@dataclass
class StepStats:
    """What one step did: pressure-solver iterations and final relative residual, the IC(0)
    diagonal shift used (0: none needed), free-surface and dead particle counts, and the wall
    time of each phase (s)."""

    iterations: int = 0
    residual: float = 0.0
    ic_shift: float = 0.0
    surface: int = 0
    dead: int = 0
    seconds: dict[str, float] = field(default_factory=dict)


class PhaseTimer:
    """Wall time (s) of named phases, added into ``seconds`` by phase name: ``with
    timer("solve"): ...`` adds the time the block took to ``seconds["solve"]``."""

    def __init__(self, seconds: dict[str, float] | None = None) -> None:
        self.seconds = {} if seconds is None else seconds

    @contextmanager
    def __call__(self, name: str) -> Iterator[None]:
        start = _time.perf_counter()
        yield
        self.seconds[name] = self.seconds.get(name, 0.0) + _time.perf_counter() - start


class SolverSetup(NamedTuple):
    """What every solver of :class:`MPSParameters` derives from them and the initial particles
    alike, the CPU's and the GPU's (:func:`solver_setup`)."""

    positions: np.ndarray  # (N, dim) float64 m, checked
    kind: np.ndarray  # (N,) int8 FLUID, WALL or DUMMY, a copy
    reference: dict[str, LatticeReference]  # per weight's radius: n0 and lambda, Eq. (F2-F3)
    constants: kernels.Constants
    search_radius: float  # m: the neighbour lists' reach
    domain_min: np.ndarray  # (dim,) m: a particle leaving the box escapes
    domain_max: np.ndarray  # (dim,) m


def solver_setup(params: MPSParameters, positions: np.ndarray, kinds: np.ndarray) -> SolverSetup:
    """Check the particles against ``params`` and derive the reference values (Eq. F2-F3), the
    kernels' constants, the search radius and the domain (``params``' or, unset, the particles'
    box widened by its size on every side). Raises ValueError for arrays of the wrong shape."""
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 2 or positions.shape[1] != params.dim:
        raise ValueError(f"positions must be (N, {params.dim}), not {positions.shape}")
    if kinds.shape != (positions.shape[0],):
        raise ValueError("kinds must be (N,)")
    l0, dim, lattice = params.l0, params.dim, params.lattice
    number_density = lattice_reference(dim, l0, params.re_number_density, lattice)
    gradient = lattice_reference(dim, l0, params.re_gradient, lattice)
    laplacian = lattice_reference(dim, l0, params.laplacian_radius, lattice)
    constants = kernels.Constants(
        dim=dim,
        re_number_density=params.re_number_density * l0,
        re_gradient=params.re_gradient * l0,
        re_laplacian=params.laplacian_radius * l0,
        n0=number_density.n0,
        n0_gradient=gradient.n0,
        n0_laplacian=laplacian.n0,
        lambda_laplacian=laplacian.lambda_,
        density=params.density,
        kinematic_viscosity=params.kinematic_viscosity,
    )
    if params.domain_min is None or params.domain_max is None:
        low = positions.min(axis=0)
        high = positions.max(axis=0)
        size = high - low
        domain_min, domain_max = low - size, high + size
    else:
        domain_min = np.asarray(params.domain_min, dtype=np.float64)
        domain_max = np.asarray(params.domain_max, dtype=np.float64)
    return SolverSetup(
        positions=positions,
        kind=kinds.astype(np.int8).copy(),
        reference={"number_density": number_density, "gradient": gradient, "laplacian": laplacian},
        constants=constants,
        search_radius=params.neighbour_radius * l0,
        domain_min=domain_min,
        domain_max=domain_max,
    )


class MPSSolver:
    """An MPS fluid: live state arrays mutated in place by :meth:`step`.

    State (N particles, D = ``params.dim``): ``position`` (N, D) m, ``velocity`` (N, D) m/s,
    ``pressure`` (N,) Pa (also the warm start of the next solve), ``number_density`` (N,)
    dimensionless (n* of the last step; 0 for dummies, which get no neighbour-list row),
    ``alive`` (N,) bool, ``kind`` (N,) int8, ``time`` s.
    Walls and dummies keep their velocity (zero for a fixed tank) and position. Dummy particles
    only add number density: their pressure is 0 and they are ignored by the gradient. Negative
    pressures of the solution are clipped to 0.
    """

    def __init__(self, params: MPSParameters, positions: np.ndarray, kinds: np.ndarray) -> None:
        setup = solver_setup(params, positions, kinds)
        self.params = params
        dim = params.dim
        self.reference = setup.reference
        self.constants = setup.constants
        self.search_radius = setup.search_radius
        # The number-density and gradient radius (m): the kernels of those radii read the lists
        # cut to it (fluid.neighbours.near_neighbours), the same sums bit for bit.
        self.near_radius = max(self.constants.re_number_density, self.constants.re_gradient)
        n = setup.positions.shape[0]
        self.position = setup.positions.copy()
        self.velocity = np.zeros((n, dim))
        self.pressure = np.zeros(n)
        self.number_density = np.zeros(n)
        self.alive = np.ones(n, dtype=np.bool_)
        self.kind = setup.kind
        self.time = 0.0
        self.domain_min = setup.domain_min
        self.domain_max = setup.domain_max
        # scratch
        self._position = np.empty_like(self.position)
        self._velocity = np.empty_like(self.velocity)
        self._acceleration = np.empty_like(self.velocity)
        self._start_position = np.empty_like(self.position)  # r^k, during a step
        self._neighbour_count = np.zeros(n, dtype=np.int64)
        self._start_number_density = np.zeros(n)  # n^k, mixed source only
        self._row_of = np.empty(n, dtype=np.int64)
        # Verlet list (neighbour_skin > 0): candidates within search_radius + skin of each
        # particle at the reference positions; None until the first use.
        self._candidates: Neighbours | None = None
        self._reference_position = np.empty_like(self.position)
        self._reference_alive = np.zeros(n, dtype=np.bool_)
        self._filter_scratch = np.empty(0)  # a float per Verlet candidate (filter_with_near)
        self.searches = 0  # cell searches so far (neighbour lists built from scratch)
        # Buffers kept from step to step for the large arrays (fluid.neighbours.room): the lists
        # at r^k and r*, the Verlet list, the near list (r^k's until the collisions are done,
        # then r*'s), and the PPE matrix (two orders, integer and real each).
        self._buffers: dict[str, list[np.ndarray]] = {
            name: [np.empty(0, dtype=np.int32), np.empty(0)]
            for name in ("start", "star", "candidates", "near")
        }
        real = MATRIX_PRECISIONS[params.matrix_precision]  # the off-diagonal entries
        self._matrix_buffers: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] = (
            np.empty(0, dtype=np.int32), np.empty(0, dtype=real), np.empty(0, dtype=np.int32),
            np.empty(0, dtype=real),
        )  # fmt: skip

    # ------------------------------------------------------------------------------ time step

    def begin_frame(self) -> None:
        """Called by the frame loop before a frame's steps (:func:`jellysim.fluid.frames.
        advance_to`). Nothing of this solver's is tied to frames; the GPU's makes its coarse
        space anew there, so that a run resumed from a frame's checkpoint steps as the run."""

    def stable_dt(self, external_acceleration: float = 0.0) -> float:
        """The largest step the stability limits allow (s): the least of :func:`step_limits`
        for the live fluid particles' largest speed and their extent along gravity."""
        p = self.params
        fluid = self.alive & (self.kind == FLUID)
        speed = height = None
        if fluid.any():
            speed = float(np.sqrt((self.velocity[fluid] ** 2).sum(axis=1)).max())
            g = p.gravity_vector
            axis = g / np.linalg.norm(g) if np.any(g) else np.eye(p.dim)[-1]
            along = self.position[fluid] @ axis
            height = float(along.max() - along.min()) + p.l0
        return min(step_limits(p, speed, height, external_acceleration).values(), default=math.inf)

    def step(self, dt: float, external_force: np.ndarray | None = None) -> StepStats:
        """Advance the fluid by ``dt`` (s), in place.

        ``external_force`` (N, D) N/m3: a force density on fluid particles (a spring force on a
        particle divided by its volume l0^D), added to gravity in the explicit stage as
        ``external_force / density``. Raises :class:`FluidDiverged` when the pressure solve does
        not converge within ``max_iterations`` or leaves non-finite values; the state is then
        that of the failed step.
        """
        stats = StepStats()
        timer = PhaseTimer(stats.seconds)
        with timer("neighbours"):
            # Neighbours at r^k, and n^k for the mixed source [Tanaka & Masunaga 2010], Eq. (F2)
            start, near = self._start_neighbours()
        with timer("explicit"):
            # Explicit stage: viscosity, gravity, external force, Eq. (F5); collisions, Eq. (F6)
            self._explicit_stage(dt, start, external_force)
            self._collide(dt, start, near)
        with timer("neighbours"):
            # Rows at r*: the fluid and the walls it reaches within the step
            wet = self._wet(start)
        # Neighbours, number density n*, free surface and PPE at r*, Eq. (F2), (F7)-(F9)
        system = self.poisson_system(
            dt,
            timer,
            reuse=True,
            rows=wet,
            start_density=self._start_number_density if self.params.source == "mixed" else None,
        )
        stats.surface = system.surface
        with timer("solve"):
            # Pressure by ICCG, CG or deflated CG, warm-started, Eq. (F11)-(F12)
            stats.iterations, stats.residual, stats.ic_shift = self._solve_pressure(system)
        with timer("correction"):
            # Pressure gradient and correction, Eq. (F10) or (F10a), (F13)
            self._correct(dt, system)
            self.time += dt
            # the corrected state; particles that left the domain or stopped being finite die
            stats.dead = kernels.commit_step(
                self.position, self.velocity, self._position, self._velocity, self.pressure,
                self.kind, self.alive, self.domain_min, self.domain_max,
            )  # fmt: skip
        return stats

    def _start_neighbours(self) -> tuple[Neighbours, Neighbours]:
        """The neighbour list at r^k (the "start" buffers), with rows for the particles the
        explicit stage moves and, for the mixed source, the walls, whose n^k enters the PPE, and
        its entries within the near radius (:meth:`near`); for the mixed source also n^k, Eq.
        (F2), into ``_start_number_density``."""
        p = self.params
        c = self.constants
        moving = self.kind == FLUID if p.source == "standard" else self.kind != DUMMY
        start, near = self.neighbours_and_near(moving, "start", "near")
        if p.source == "mixed":
            kernels.number_density(
                near, self.alive, c.re_number_density, self._start_number_density,
                self._neighbour_count,
            )  # fmt: skip
        return start, near

    def _explicit_stage(
        self, dt: float, start: Neighbours, external_force: np.ndarray | None
    ) -> None:
        """u* and r* of Eq. (F5) (viscosity, gravity and ``external_force / density``) into the
        scratch ``_velocity`` and ``_position``; r^k kept in ``_start_position`` (:meth:`_wet`)."""
        p = self.params
        self._start_position[:] = self.position
        self._acceleration[:] = p.gravity_vector
        if external_force is not None:
            self._acceleration += external_force / p.density
        kernels.explicit_stage(
            self.position, self.velocity, self.kind, self.alive, start, self.constants,
            self._acceleration, dt, self._position, self._velocity,
        )  # fmt: skip

    def _collide(self, dt: float, start: Neighbours, near: Neighbours) -> None:
        """The collision model, Eq. (F6), from the scratch r*, u* into ``position`` and
        ``velocity``. The r^k list holds every pair closer than the collision distance at r* (a
        particle moves well under l0 in the explicit stage); so does its near part where the
        collision distance is at least COLLISION_MARGIN inside the near radius, and the
        pairs, taken in the same order, are the same."""
        p = self.params
        within = (p.collision_distance + COLLISION_MARGIN) * p.l0 <= near.radius
        kernels.collision(
            self._position, self._velocity, self.kind, self.alive, near if within else start,
            p.collision_distance * p.l0, p.collision_restitution, dt,
            self.position, self.velocity,
        )  # fmt: skip

    def _solve_pressure(self, system: PoissonSystem) -> tuple[int, float, float]:
        """Solve ``system`` with the ``solver`` by name, warm-started from the last pressure, Eq.
        (F11)-(F12), into ``pressure`` (0 off the unknowns, negative pressures clipped to 0).
        Returns the iterations, the final relative residual and the IC(0) diagonal shift; raises
        :class:`FluidDiverged` when the solve fails or stops short of ``tolerance``."""
        p = self.params
        particles = system.particles
        solution = self.pressure[particles]
        try:
            coarse = CoarseSpace(self.position[particles], self.domain_min, p.coarse_cell * p.l0)
            iterations, residual, ic_shift = solve(
                system.matrix, system.rhs, solution, p.solver, p.tolerance, p.max_iterations,
                coarse,
            )  # fmt: skip
        except FluidDiverged as error:
            raise FluidDiverged(
                str(error), time=self.time, iterations=0, residual=math.inf
            ) from None
        if not (residual <= p.tolerance and np.all(np.isfinite(solution))):
            raise FluidDiverged(
                f"pressure solve stopped at relative residual {residual:.3g} after "
                f"{iterations} iterations (tolerance {p.tolerance:.3g}); reduce the time step",
                time=self.time,
                iterations=iterations,
                residual=residual,
            )
        self.pressure[:] = 0.0
        self.pressure[particles] = np.maximum(solution, 0.0)
        return iterations, residual, ic_shift

    def _correct(self, dt: float, system: PoissonSystem) -> None:
        """The pressure gradient, Eq. (F10), (F10a) or (F10c) (and (F10b) with
        ``surface_repulsion``), and the velocity and position correction, Eq. (F13), into the
        scratch ``_position`` and ``_velocity`` (:func:`kernels.commit_step` takes them)."""
        p = self.params
        if p.gradient == "conservative":
            kernels.conservative_pressure_correction(
                self.position, self.velocity, self.pressure, self.kind, self.alive,
                system.near, self.constants, dt, self._position, self._velocity,
            )  # fmt: skip
            return
        surface = (  # the fluid particles on the free surface, for Eq. (F10b)
            self.alive & (self.kind == FLUID) & ~system.unknown if p.surface_repulsion else None
        )
        kernels.pressure_correction(  # Eq. (F10b)'s normal reaches the Laplacian radius
            self.position, self.velocity, self.pressure, self.kind, self.alive,
            system.near, self.constants, dt, self._position, self._velocity,
            p.gradient == "corrected", surface, system.neighbours,
        )  # fmt: skip

    def neighbours(self, rows: np.ndarray, buffer: str | None = None) -> Neighbours:
        """The neighbours within ``search_radius`` of the live particles with ``rows[i]`` ((N,)
        bool, no dummies) at the current positions. In arrays of their own, or with
        ``buffer`` in the solver's buffers of that name ("start" for the list at the start of a
        step, "star" for the one at r*), valid until the next list in the same buffers.

        With ``neighbour_skin`` 0, a cell search. Otherwise cut from the Verlet list
        (:meth:`_verlet_list`)."""
        p = self.params
        if p.neighbour_skin <= 0.0:
            self.searches += 1
            index, distance = self._buffer(buffer)
            return self._keep(
                buffer,
                search_neighbours(
                    self.position,
                    self.alive,
                    rows,
                    self.search_radius,
                    index,
                    distance,
                    wave_chunks(),
                ),
                self.search_radius,
            )
        index, distance = self._buffer(buffer)
        no_index, no_distance = self._buffer(None)
        lists = filter_with_near(
            self._verlet_list(), self.position, self.alive, rows, self.search_radius,
            index, distance, 0.0, no_index, no_distance, self._filter_scratch,
        )  # fmt: skip
        self._filter_scratch = lists[6]
        return self._keep(buffer, lists[:3], self.search_radius)

    def neighbours_and_near(
        self, rows: np.ndarray, buffer: str | None = None, near_buffer: str | None = None
    ) -> tuple[Neighbours, Neighbours]:
        """:meth:`neighbours` and its entries within :attr:`near_radius` (:meth:`near`), in
        the buffers ``buffer`` and ``near_buffer`` (None: arrays of their own). A cell search
        (``neighbour_skin`` 0) cuts the near list as it copies the rows to their place; the cut
        from the Verlet list makes both lists in the same two passes
        (:func:`~jellysim.fluid.neighbours.filter_with_near`)."""
        if self.near_radius >= self.search_radius:
            whole = self.neighbours(rows, buffer)
            return whole, self.near(whole, near_buffer)
        index, distance = self._buffer(buffer)
        near_index, near_distance = self._buffer(near_buffer)
        if self.params.neighbour_skin > 0.0:
            filtered = filter_with_near(
                self._verlet_list(), self.position, self.alive, rows, self.search_radius,
                index, distance, self.near_radius, near_index, near_distance,
                self._filter_scratch,
            )  # fmt: skip
            self._filter_scratch = filtered[6]
            lists, near_lists = filtered[:3], filtered[3:6]
        else:
            self.searches += 1
            searched = search_with_near(
                self.position, self.alive, rows, self.search_radius, index, distance,
                self.near_radius, near_index, near_distance, wave_chunks(),
            )  # fmt: skip
            lists, near_lists = searched[:3], searched[3:]
        whole = self._keep(buffer, lists, self.search_radius)
        return whole, self._keep(near_buffer, near_lists, self.near_radius)

    def near(self, neighbours: Neighbours, buffer: str | None = None) -> Neighbours:
        """The entries of ``neighbours`` within :attr:`near_radius`, in its order
        (:func:`~jellysim.fluid.neighbours.near_neighbours`), in the buffers ``buffer`` like
        :meth:`neighbours`; ``neighbours`` itself where its radius is no larger."""
        if neighbours.radius <= self.near_radius:
            return neighbours
        arrays = near_neighbours(neighbours, self.near_radius, *self._buffer(buffer))
        return self._keep(buffer, arrays, self.near_radius)

    def _keep(
        self, buffer: str | None, arrays: tuple[np.ndarray, np.ndarray, np.ndarray], radius: float
    ) -> Neighbours:
        """A list returned by a kernel into the buffers ``buffer``: the buffers (perhaps grown)
        kept for next time (``buffer`` None: the arrays are the list's own), the list cut to its
        length."""
        start, index, distance = arrays
        if buffer is not None:
            self._buffers[buffer] = [index, distance]
        end = int(start[-1])
        return Neighbours(start, index[:end], distance[:end], radius)

    def _buffer(self, name: str | None) -> list[np.ndarray]:
        """The buffers ``name`` (index and distance), or empty arrays for ``None``."""
        if name is None:
            return [np.empty(0, dtype=np.int32), np.empty(0)]
        return self._buffers[name]

    def _verlet_list(self) -> Neighbours:
        """The Verlet list, searched again (at the current positions, the radius widened by
        the skin) when it is missing or when a live particle has moved more than half the skin
        since it was built: until then it holds every pair now closer than the radius."""
        p = self.params
        if (
            self._candidates is None
            or largest_displacement(self.position, self._reference_position, self.alive)
            > 0.5 * p.neighbour_skin * p.l0
        ):
            self._reference_position[:] = self.position
            self._reference_alive[:] = self.alive
            self._build_candidates()
        assert self._candidates is not None
        return self._candidates

    def _build_candidates(self) -> None:
        """The Verlet list at the reference positions (a function of those and the reference
        live set only, so a resumed run rebuilds the very same list)."""
        p = self.params
        radius = self.search_radius + p.neighbour_skin * p.l0
        self.searches += 1
        self._candidates = None  # its arrays are the buffers about to be overwritten
        index, distance = self._buffers["candidates"]
        self._candidates = self._keep(
            "candidates",
            search_neighbours(
                self._reference_position,
                self._reference_alive,
                self.kind != DUMMY,
                radius,
                index,
                distance,
                wave_chunks(),
            ),
            radius,
        )

    def _wet(self, start: Neighbours) -> np.ndarray | None:
        """The particles that need a row at r*: the live fluid particles and the walls that
        were within the search radius of one at the start of the step (``start``, the list
        at r^k, fluid rows), provided no particle has moved by more than the search radius
        less the number-density radius in between (else None: every live fluid and wall
        particle).

        A wall with no fluid particle within the number-density radius has the number density
        of its fixed wall and dummy neighbours alone, below beta n0 (one side of it is empty):
        it is on the free surface (p = 0, no equation) whether or not its row is built, so
        leaving out these rows changes nothing but the work (a third of the rows in the
        benchmark's 3-D tank) and the number density stored for such walls (0, like dummies).
        """
        p = self.params
        margin = self.search_radius - p.re_number_density * p.l0
        fluid_rows = np.flatnonzero(self.alive & (self.kind == FLUID))
        if start.radius < self.search_radius or (
            largest_displacement(self.position, self._start_position, self.alive) > margin
        ):
            return None
        return listed(start, fluid_rows) & (self.kind == WALL) | (self.alive & (self.kind == FLUID))

    def poisson_system(
        self,
        dt: float,
        timer: PhaseTimer | None = None,
        reuse: bool = False,
        rows: np.ndarray | None = None,
        start_density: np.ndarray | None = None,
    ) -> PoissonSystem:
        """The pressure Poisson equation at the current positions (taken as r*): neighbours,
        number density n* (stored in ``number_density``), free-surface particles (Dirichlet
        p = 0, Eq. F7) and ``A p = b`` over the other live fluid and wall particles (Eq. F8).
        ``timer`` (if given) records the phases "neighbours" and "assembly".
        ``reuse``: the matrix and neighbour list are written into the solver's buffers (as
        :meth:`step` does), valid until the next step or call; otherwise arrays of their own.
        ``rows``: the particles given a neighbour-list row ((N,) bool; :meth:`_wet`), by
        default every live fluid and wall particle; the others are on the free surface.
        ``start_density``: n^k ((N,), the number density at the start of the step), which the
        "either-density" criterion also tests; without it that criterion tests n* alone."""
        if timer is None:
            timer = PhaseTimer()
        c = self.constants
        # Dummies need no row: they only complete the number density of their neighbours.
        solid = self.alive & (self.kind != DUMMY)
        with timer("neighbours"):
            # Neighbours and number density n* at r*, Eq. (F2)
            nb, near = self.neighbours_and_near(
                solid if rows is None else rows & solid,
                "star" if reuse else None,
                "near" if reuse else None,
            )
            kernels.number_density(
                near, self.alive, c.re_number_density, self.number_density, self._neighbour_count
            )
        with timer("assembly"):
            # Free surface, Eq. (F7) or (F7b); the other particles are the unknowns
            surface = self._free_surface(solid, start_density)
            unknown = solid & ~surface
            # Matrix A, Eq. (F8), and source b, Eq. (F8)-(F9)
            matrix, particles = self._poisson_matrix(dt, nb, unknown, reuse)
            rhs = self.poisson_source(dt, particles, near)
        return PoissonSystem(matrix, rhs, unknown, particles, int(surface.sum()), nb, near)

    def _free_surface(self, solid: np.ndarray, start_density: np.ndarray | None) -> np.ndarray:
        """The particles of ``solid`` ((N,) bool) on the free surface ((N,) bool) by the
        ``surface`` criterion, Eq. (F7) or (F7b), from n* (``number_density``), the neighbour
        counts and, for "either-density", n^k ``start_density``."""
        p = self.params
        c = self.constants
        surface = self.number_density < p.beta * c.n0
        if p.surface == "neighbour-count":
            count0 = self.reference["number_density"].count
            surface |= self._neighbour_count < p.surface_neighbour_threshold * count0
        if p.surface == "either-density" and start_density is not None:
            surface |= start_density < p.beta * c.n0  # n^k too (docs/theory/fluid.md F7b)
        surface &= solid
        return surface

    def _poisson_matrix(
        self, dt: float, nb: Neighbours, unknown: np.ndarray, reuse: bool
    ) -> tuple[Matrix, np.ndarray]:
        """The matrix A of Eq. (F8) over the ``unknown`` particles ((N,) bool), and the
        particle of each row ((n,) int64; rows in the two-block order of :class:`Matrix`).
        ``reuse``: built in the solver's matrix buffers (see :meth:`poisson_system`)."""
        p = self.params
        c = self.constants
        blocks = number_unknowns(
            unknown, self.position, c.re_laplacian, TWO_BLOCK_ROWS, self._row_of
        )
        n_rows = int(blocks[2])
        particles = np.empty(n_rows, dtype=np.int64)
        particles[self._row_of[unknown]] = np.flatnonzero(unknown)
        shift = p.density * p.compressibility / dt**2
        ordered = p.solver != "deflated"  # the deflated solver needs no column order
        no_int = np.empty(0, dtype=np.int32)
        no_real = np.empty(0, dtype=MATRIX_PRECISIONS[p.matrix_precision])
        if self._matrix_buffers[1].dtype != no_real.dtype:  # params changed since the last
            self._matrix_buffers = (no_int, no_real, no_int, no_real)
        buffers = self._matrix_buffers if reuse else (no_int, no_real, no_int, no_real)
        indptr, indices, data, diagonal, spare_indices, spare_data, value = assemble_poisson(
            nb, self.kind, self.alive, self._row_of, n_rows, c, shift, ordered, buffers
        )
        if reuse and ordered:
            self._matrix_buffers = (spare_indices, spare_data, indices, data)
        elif reuse:
            self._matrix_buffers = (indices, data, spare_indices, spare_data)
        nnz = int(indptr[-1])
        matrix = Matrix(indptr, indices[:nnz], data[:nnz], diagonal, blocks[:2].copy(), value)
        return matrix, particles

    def poisson_source(
        self, dt: float, particles: np.ndarray, neighbours: Neighbours
    ) -> np.ndarray:
        """Right-hand side b of ``A p = b`` for the unknown particles ``particles`` ((n,) int64,
        in row order) (Pa/m2), Eq. (F8)-(F9):
        standard ``(rho/dt^2)(n* - n0)/n0``; mixed ``-(rho/dt) div u* + gamma (rho/dt^2)
        (n^k - n0)/n0`` (n^k from the start of the step)."""
        p = self.params
        c = self.constants
        if p.source == "standard":
            deviation = (self.number_density[particles] - c.n0) / c.n0
            return p.density / dt**2 * deviation
        divergence = np.zeros(self.pressure.shape[0])
        kernels.velocity_divergence(
            self.position, self.velocity, self.kind, self.alive, neighbours, c, divergence,
        )  # fmt: skip
        deviation = (self._start_number_density[particles] - c.n0) / c.n0
        return -p.density / dt * divergence[particles] + (
            p.mixed_relaxation * p.density / dt**2 * deviation
        )

    def pressure_gauge(
        self, rows: Sequence[np.ndarray], weights: Sequence[np.ndarray]
    ) -> Callable[[], np.ndarray]:
        """A function giving (K,) Pa, ``sum_j weights[k][j] pressure[rows[k][j]]`` for each of
        the K pairs of ``rows`` (int) and ``weights`` (float), at the pressure when it is called
        (the wall-pressure probes, Eq. F15): :func:`~jellysim.fluid.probes.weighted_sums`."""
        return lambda: weighted_sums(self.pressure, rows, weights)

    # ---------------------------------------------------------------------------- checkpoints

    def state_arrays(self) -> dict[str, np.ndarray]:
        """Copies of everything a bitwise resume needs (the pressure is the warm start; with a
        neighbour skin, the positions and live set the Verlet list was built at, from which
        :meth:`restore` builds it again)."""
        arrays = {
            "position": self.position.copy(),
            "velocity": self.velocity.copy(),
            "pressure": self.pressure.copy(),
            "number_density": self.number_density.copy(),
            "alive": self.alive.copy(),
            "kind": self.kind.copy(),
            "time": np.array(self.time),
        }
        if self._candidates is not None:
            arrays["neighbour_reference_position"] = self._reference_position.copy()
            arrays["neighbour_reference_alive"] = self._reference_alive.copy()
        return arrays

    def restore(self, arrays: dict[str, np.ndarray]) -> None:
        """Load a :meth:`state_arrays` dictionary into the live arrays (in place)."""
        for name in ("position", "velocity", "pressure", "number_density", "alive", "kind"):
            target = getattr(self, name)
            if arrays[name].shape != target.shape:
                raise ValueError(f"{name}: shape {arrays[name].shape}, expected {target.shape}")
            target[...] = arrays[name]
        self.time = float(arrays["time"])
        self._candidates = None
        if "neighbour_reference_position" in arrays and self.params.neighbour_skin > 0.0:
            self._reference_position[:] = arrays["neighbour_reference_position"]
            self._reference_alive[:] = arrays["neighbour_reference_alive"]
            self._build_candidates()


def substep(remaining: float, limit: float) -> float:
    """The step (s) that covers ``remaining`` (s) in equal steps of at most ``limit`` (s).

    Landing on a frame time by shortening the last step would leave an arbitrarily short step,
    and the standard source divides the number-density error left by the steps before by dt^2:
    a step of 1e-6 s then corrects that error as fully as a whole step does, and the velocity
    change (that displacement over dt) becomes a kick. Equal steps keep every step above half
    the limit.
    """
    if remaining <= limit:
        return remaining
    return remaining / math.ceil(remaining / limit)


__all__ = [
    "LatticeReference",
    "MPSParameters",
    "MPSSolver",
    "StepStats",
    "lattice_reference",
    "step_limits",
    "substep",
]
