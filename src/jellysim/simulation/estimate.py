"""Costs known before they are paid (issue 24): a run's memory, disk and time, estimated from the
scene alone before any of its arrays is allocated, and the check that refuses a run the machine
cannot hold.

- **Memory**: the peak resident bytes of the arrays the run holds, by part (:class:`Costs`
  ``memory``): the tentacle chains and their per-frame samples; the MPS particles' state, their
  two neighbour lists (and the Verlet list), the cell grid, the Poisson matrix and the pressure
  solver's preconditioner (IC(0) or the deflated solver's coarse space and SuperLU factor); the
  soft bell's springs and skin; the result writer's buffered frames and HDF5 chunk caches; the
  checkpoint's copy of the state. Particle counts are the lattice's sites per volume (the tank's
  walls and dummies, the water, the bell's shell), neighbour counts those of the full lattice
  neighbourhood (:func:`jellysim.fluid.mps.lattice_reference`): every part is an upper bound of
  the same order as the real one, and their sum is compared with the measured peak in
  tests/unit/test_estimate.py.
- **Disk**: ``result.h5``, every per-frame dataset of :mod:`jellysim.fields` the loop writes in
  whole HDF5 chunks (:func:`jellysim.io.result.chunk_rows`), the static ones, the checkpoint
  (twice: the next is written beside the last before it replaces it) and ``scene.toml``.
- **Time**: frames x (MPS steps a frame x fluid particles x :data:`FLUID_SECONDS_PER_PARTICLE_STEP`
  + tentacle substeps a frame x tentacle particles x
  :data:`TENTACLE_SECONDS_PER_PARTICLE_SUBSTEP` + :data:`FRAME_SECONDS`): the substeps from the
  tentacles' plan (:func:`jellysim.tentacle.model.plan_substeps`), the MPS step from the fluid's
  stability limits at the start (:func:`jellysim.fluid.mps.step_limits`; the water at rest, the
  soft bell's margin at its full speed). A rough figure: the constants were measured on a 2-core
  host (docs/decisions.md, "Costs before they are paid").
- **On a GPU** (``fluid.device = "cuda"``): the solver's arrays are the GPU's (:class:`Costs`
  ``gpu_memory``, as :class:`jellysim.fluid.gpu.GPUSolver` allocates them, compared in the CUDA
  simulator in tests/unit/test_estimate.py), checked against the GPU's free memory; the host
  keeps the state's frame copies; the MPS step takes :func:`gpu_step_seconds` and the run
  :data:`GPU_START_SECONDS` more (an H200's, docs/performance.md).

A fluid that would need more than :data:`jellysim.fluid.frames.MAX_STEPS_PER_FRAME` MPS steps a
frame, or tentacles more than their substep cap, are refused here (exit 2) whatever the machine.
"""

from __future__ import annotations

import logging
import math
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numba
import numpy as np

from jellysim import fields
from jellysim.bell import make_root_driver
from jellysim.bell.kinematic import MESH_RINGS, bell_faces, sector_count
from jellysim.bell.skin import SKIN_RADIUS
from jellysim.bell.soft import explicit_spring_dt, margin_forcing
from jellysim.config import Scene, scene_to_toml
from jellysim.coupling.bell_in_fluid import water_parameters
from jellysim.errors import InputError
from jellysim.fields import Dataset
from jellysim.fluid.frames import MAX_STEPS_PER_FRAME, steps_per_frame
from jellysim.fluid.geometry import (
    DUMMY_LAYERS,
    ROW_HEIGHT,
    SITE_VOLUME,
    WALL_LAYERS,
    filled_height,
)
from jellysim.fluid.mps import MPSParameters, lattice_reference, step_limits
from jellysim.fluid.neighbours import CELLS_PER_RADIUS
from jellysim.fluid.setup import mps_parameters
from jellysim.io.result import BATCH_FRAMES, BATCH_SECONDS, chunk_rows, frame_bytes, frame_datasets
from jellysim.simulation.fluid import fluid_datasets
from jellysim.simulation.loop import loop_name
from jellysim.tentacle.kernels import KKT_BLOCK, KKT_HALF_BANDWIDTH
from jellysim.tentacle.layout import root_layout
from jellysim.tentacle.model import SubstepPlan, plan_substeps
from jellysim.tentacle.roots import Forcing

log = logging.getLogger(__name__)

# Wall time of one MPS step per fluid particle, and of one tentacle substep per tentacle
# particle, on two cores; and the Python work of a frame (roots, noise, writing). Chosen from the
# measurements on this project's 2-core host listed in docs/decisions.md ("Costs before they are
# paid") and docs/performance.md.
FLUID_SECONDS_PER_PARTICLE_STEP = 1.0e-5
# The same on a GPU (fluid.device = "cuda"), from docs/performance.md's H200 runs (2026-11-27).
# The water's step is a fixed cost (launches and barriers) plus a cost per slot of the neighbour
# lists (all particles x the lists' width), which the search and the Poisson rows scale with:
# fitted to moon-jelly's water (84,588 particles, 9.6 ms) and tank-3d at a million (1,595,308,
# 67.6 ms); tank-3d at 54,000 (11.2 ms measured, 11.6 by this) and SPHERIC Test 2 at 1.1 million
# (113.6 ms, 99.7 by this; its lists are wider) were not fitted.
GPU_SECONDS_PER_STEP = 6.3e-3
GPU_SECONDS_PER_SLOT = 2.14e-10
# A soft bell's springs, muscle and implicit solve on the GPU, a step: a fixed part plus a part
# per spring, fitted to moon-jelly's three pulses (74 s for 1,440 steps, 17,556 springs) and
# moon-jelly-fine's (about 16 min for 2,400 steps, 694,236 springs, projected from 62 of its
# 120 frames with its tentacles). The runs' other work (the tentacles, the writing) is in them.
GPU_SECONDS_PER_BELL_STEP = 2.4e-2
GPU_SECONDS_PER_SPRING_STEP = 4.3e-7
# A GPU run compiles its CUDA kernels each time (Numba does not cache them) and builds its arrays
# on the device: its set-up and first step took 10.9 s at 57,600 and 15.0 s at 1.1 M particles.
GPU_START_SECONDS = 15.0
TENTACLE_SECONDS_PER_PARTICLE_SUBSTEP = 1.0e-6
FRAME_SECONDS = 2.0e-3
# A run estimated to take longer says so, in one line, before it starts.
LONG_RUN_SECONDS = 600.0

FLOAT, INDEX, LONG = 8, 4, 8  # float64 values, int32 neighbour and column indices, int64
SINGLE = 4  # a float32 value (the PPE matrix's entries with fluid.matrix_precision "single")
# Per MPS particle: seven (N, D) float arrays (position, velocity and their step copies,
# acceleration, start and Verlet reference positions), five (N,) 8-byte ones (pressure, number
# densities, neighbour count, row number) and three of bytes (alive, kind, reference alive).
STATE_BYTES = (7, 5 * FLOAT + 3)  # (float vectors, scalar bytes)
# The cell grid of a neighbour search: cell coordinates and member order (int64 x 4), the
# coordinates twice in cell order (float64 x 3 each) and the cell of each particle.
GRID_BYTES_PER_PARTICLE = 12 * LONG
# HDF5 keeps each open dataset's chunks in a cache of 1 MiB (h5py's default).
CHUNK_CACHE_BYTES = 2**20
# The writer buffers frames for a second: on a machine this much faster than the time estimate's
# it buffers this many times more of them.
FASTER_MACHINE = 4.0
# What any run holds besides its arrays: the HDF5 library's state for the open result, the
# loop's Python objects. Measured: a run of one tentacle of 3 particles peaks 2.1 MiB above the
# process it starts in.
RUN_OVERHEAD_BYTES = 2 * 2**20
# SuperLU's factor of the deflated solver's coarse matrix (MMD on A^T + A, symmetric mode), in
# entries, fitted to measured factors of m-row 9- and 27-point grid matrices (m = 450 to 500,000
# in 2-D, 297 to 157,500 in 3-D): about 8 m ln m in 2-D and 8 m^1.45 in 3-D.
LU_FILL = 8.0
# Soft bell springs at one particle, for the explicit springs' step bound, as fractions of the
# full lattice neighbourhood within bell.spring_radius: the largest count of passive and of muscle
# springs at one particle of bells two or three layers thick (34 and 8-15 of 56 at 2.4 l0 in
# moon-jelly, moon-jelly-weightless and moon-jelly-real-size; moon-jelly-fine's six layers have 56
# and 18, its springs implicit). The springs' count: _spring_count.
PASSIVE_SPRING_SHARE = 0.6
MUSCLE_SPRING_SHARE = 0.2


@dataclass(frozen=True)
class Particles:
    """A fluid scene's MPS particles, estimated from the lattice's sites per volume: ``fluid``
    (the water and the soft bell's particles, which are fluid in every stage but the explicit
    one), ``bell`` (of those, the bell's), ``walls`` and ``dummies`` (the tank), in ``dim``
    dimensions; ``wetted`` the walls the water reaches (the floor's, the sides' up to the
    water's height and a neighbour radius), which get rows in the neighbour list at r* and the
    pressure equation."""

    fluid: int
    bell: int
    walls: int
    dummies: int
    dim: int
    wetted: int

    @property
    def total(self) -> int:
        return self.fluid + self.walls + self.dummies


@dataclass(frozen=True)
class Costs:
    """What a run will cost: ``memory`` and ``disk`` in bytes by part, ``seconds`` of wall time
    on a machine like this project's 2-core host, ``frames`` to compute, ``plan`` the substeps in
    words."""

    memory: dict[str, int] = field(default_factory=dict)
    disk: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0
    frames: int = 0
    plan: str = ""
    gpu_memory: dict[str, int] = field(default_factory=dict)  # fluid.device = "cuda": the GPU's

    @property
    def memory_bytes(self) -> int:
        return sum(self.memory.values())

    @property
    def gpu_memory_bytes(self) -> int:
        return sum(self.gpu_memory.values())

    @property
    def disk_bytes(self) -> int:
        return sum(self.disk.values())

    def describe(self) -> str:
        """One line: the three estimates and the plan they rest on."""
        gpu = f" and {size(self.gpu_memory_bytes)} on the GPU" if self.gpu_memory else ""
        return (
            f"estimated cost: {size(self.memory_bytes)} of memory{gpu}, "
            f"{size(self.disk_bytes)} on disk, about {duration(self.seconds)} ({self.frames} "
            f"frames, {self.plan})"
        )


def size(count: float) -> str:
    """Bytes in words: '1.5 GiB'."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if count < 1024.0 or unit == "PiB":
            return f"{count:.0f} {unit}" if unit == "B" else f"{count:.3g} {unit}"
        count /= 1024.0
    raise AssertionError("unreachable")


def duration(seconds: float) -> str:
    """A duration in words: '40 s', '12 min', '3.5 h', '41 days'."""
    if seconds < 120.0:
        return f"{seconds:.2g} s"
    if seconds < 7200.0:
        return f"{seconds / 60.0:.0f} min"
    if seconds < 2 * 86400.0:
        return f"{seconds / 3600.0:.2g} h"
    return f"{seconds / 86400.0:.3g} days"


# ---------------------------------------------------------------------------------- particles


def particle_counts(scene: Scene) -> Particles:
    """The MPS particles of a fluid scene without building them: each lattice site stands for
    ``SITE_VOLUME l0^D``, so a region holds its volume over that (exact on the square lattice
    for the water and the tank, within a few per cent on the others and for the bell's shell)."""
    f = scene.fluid
    dim, l0 = f.dimensions, f.spacing
    site = SITE_VOLUME[f.lattice] * l0**dim
    horizontal = [f.tank_width] + ([f.tank_depth] if dim == 3 else [])
    width = f.water_width if f.geometry == "dam-break" else f.tank_width
    water = width * math.prod(horizontal[1:]) * filled_height(f.water_height, l0, f.lattice)

    def shell(layers: int, height: float) -> float:
        """The tank's walls to ``height``: its inner volume to there widened by ``layers`` l0
        behind its sides and floor, less that inner volume."""
        widened = math.prod(w + 2 * layers * l0 for w in horizontal) * (height + layers * l0)
        return widened - math.prod(horizontal) * height

    walls = shell(WALL_LAYERS, f.tank_height)
    tank = shell(WALL_LAYERS + DUMMY_LAYERS, f.tank_height)
    reach = mps_parameters(scene).neighbour_radius * l0
    wetted = shell(WALL_LAYERS, min(f.tank_height, f.water_height + reach))
    for box in f.obstacles:  # solid boxes: walls within l0 of their faces (not a floor's)
        sides = [box[k + 3] - box[k] for k in range(3)]
        on_floor = box[2] <= 0.0
        core = [max(sides[0] - 2 * l0, 0.0), max(sides[1] - 2 * l0, 0.0)]
        core.append(max(sides[2] - (1 if on_floor else 2) * l0, 0.0))
        walls += math.prod(sides) - math.prod(core)
        tank += math.prod(sides)
    bell = 0.0
    if scene.bell.model == "mass-spring":  # the shell between two half-ellipsoids (Eq. B7)
        b = scene.bell
        wall = b.thickness * b.height
        outer, inner = b.radius**2 * b.height, (b.radius - wall) ** 2 * (b.height - wall)
        bell = 2.0 / 3.0 * math.pi * (outer - inner)
    return Particles(
        fluid=round(water / site),
        bell=round(bell / site),
        walls=round(walls / site),
        dummies=round((tank - walls) / site),
        dim=dim,
        wetted=round(wetted / site),
    )


def _neighbours(params: MPSParameters, radius: float) -> int:
    """Sites within ``radius`` l0 of a site of the full lattice (itself excluded)."""
    return lattice_reference(params.dim, params.l0, radius, params.lattice).count


# ------------------------------------------------------------------------------- time steps


@dataclass(frozen=True)
class FluidPlan:
    """The MPS step at the start of a fluid scene: ``params``, ``steps`` a frame of ``dt`` (s),
    ``binding`` the limit that sets it."""

    params: MPSParameters
    steps: int
    dt: float
    binding: str


# The scene keys behind each limit of the MPS step, and the way out, for the refusal.
_LIMIT_KEYS = {
    "Courant": ("fluid.courant", "fluid.spacing", "raise fluid.courant or fluid.spacing"),
    "acceleration": ("fluid.courant", "fluid.spacing", "raise fluid.courant or fluid.spacing"),
    "viscosity": (
        "water.viscosity",
        "fluid.spacing",
        "lower water.viscosity or raise fluid.spacing",
    ),
    "springs": (
        "bell.spring_stiffness",
        "fluid.spacing",
        "lower bell.spring_stiffness or set bell.spring_integration = 'implicit'",
    ),
}


def fluid_plan(scene: Scene, counts: Particles) -> FluidPlan:
    """The MPS steps a frame at the start: the stability limits of the water at rest (floored
    at a free fall over its height where the solver floors it) or, with the soft bell, moving at
    the margin's full speed, and the explicit springs' limit. More than ``MAX_STEPS_PER_FRAME``
    steps a frame is refused with a sentence naming the keys behind the binding limit."""
    soft = scene.bell.model == "mass-spring"
    params = water_parameters(scene) if soft else mps_parameters(scene)
    f = scene.fluid
    g = params.gravity_vector
    axis = g / np.linalg.norm(g) if np.any(g) else np.eye(params.dim)[-1]
    # the extent of the water's particle centres along each axis: a spacing less than the
    # water's, a row's spacing less upwards
    width = f.water_width if f.geometry == "dam-break" else f.tank_width
    extent = [width - params.l0] + ([f.tank_depth - params.l0] if params.dim == 3 else [])
    row = ROW_HEIGHT[f.lattice] * params.l0
    extent.append(filled_height(f.water_height, params.l0, f.lattice) - row)
    height = float(np.abs(axis) @ np.array(extent)) + params.l0
    speed = margin_forcing(scene).speed if soft else 0.0
    limits = step_limits(params, speed, height)
    if soft and scene.bell.spring_integration == "explicit":
        limits["springs"] = explicit_spring_dt(
            _spring_stiffness_sum(scene, params), _cell_mass(scene)
        )
    binding = min(limits, key=limits.__getitem__) if limits else "frame"
    frame_dt = 1.0 / scene.fps
    dt = min(limits.values(), default=frame_dt)
    steps = steps_per_frame(frame_dt, dt)
    if steps > MAX_STEPS_PER_FRAME:
        first, second, way_out = _LIMIT_KEYS[binding]
        raise InputError(
            f"{first} = {_value(scene, first):g}, {second} = {_value(scene, second):g}: the "
            f"fluid would need {steps:.3g} MPS steps a frame (its {binding} limit, dt = {dt:.3g} "
            f"s), at most {MAX_STEPS_PER_FRAME:,}; {way_out}"
        )
    return FluidPlan(params, steps, dt, binding)


def _value(scene: Scene, key: str) -> float:
    table, name = key.split(".")
    return float(getattr(getattr(scene, table), name))


def _cell_mass(scene: Scene) -> float:
    """A bell particle's mass (kg): the water's in a cell of l0^3."""
    return scene.water.density * scene.fluid.spacing**3


def _spring_stiffness_sum(scene: Scene, params: MPSParameters) -> float:
    """The largest sum of spring constants at a bell particle (N/m), the muscle's fully
    stiffened: the lattice neighbourhood within bell.spring_radius, of which a shell two or three
    layers thick keeps :data:`PASSIVE_SPRING_SHARE`, :data:`MUSCLE_SPRING_SHARE` of them muscle."""
    b = scene.bell
    springs = lattice_reference(3, params.l0, b.spring_radius, "square").count
    stiffened = PASSIVE_SPRING_SHARE + MUSCLE_SPRING_SHARE * (max(b.muscle_stiffening, 1.0) - 1.0)
    return b.spring_stiffness * springs * stiffened


def _tentacle_plans(scene: Scene) -> tuple[list[SubstepPlan], int]:
    """Each tentacle group's substep plan (none without tentacles) and their margin's points."""
    if scene.tentacle_count == 0:
        return [], 0
    if loop_name(scene) == "soft-bell":
        forcing: Forcing = margin_forcing(scene)
        margin_points = sector_count(root_layout(scene).margin_sectors(), 0)
    else:
        driver = make_root_driver(scene)
        forcing = driver.forcing()
        margin_points = driver.margin(0.0).shape[0]
    plans = [plan_substeps(scene.group_scene(g), forcing) for g in range(len(scene.groups))]
    return plans, margin_points


def _tentacle_datasets(scene: Scene, margin_points: int) -> list[Dataset]:
    """The tentacles' per-frame datasets: T over every group, P the longest chain's."""
    particles = scene.tentacles.particles if len(scene.groups) == 1 else scene.max_particles
    return frame_datasets(scene.tentacle_count, particles, margin_points)


def _tentacle_static(scene: Scene) -> dict[str, int]:
    """Bytes of the static per-tentacle datasets: group and particle count, int32 each."""
    count = scene.tentacle_count
    return {fields.TENTACLE_GROUP.path: 4 * count, fields.TENTACLE_PARTICLES.path: 4 * count}


# ----------------------------------------------------------------------------------- datasets


def planned_datasets(scene: Scene) -> tuple[list[Dataset], dict[str, int]]:
    """The per-frame datasets the scene's loop will declare (their shapes from the estimated
    counts) and the bytes of its static ones, by path; tests/unit/test_estimate.py holds them
    to the loops' own."""
    name = loop_name(scene)
    if name == "tentacles":
        driver = make_root_driver(scene)
        own = _tentacle_datasets(scene, driver.margin(0.0).shape[0])
        static = {path: array.nbytes for path, (array, _) in driver.static_datasets().items()}
        return own + driver.frame_datasets(), _tentacle_static(scene) | static
    counts = particle_counts(scene)
    if name == "fluid":
        probes = [
            field.dataset(**{axis: len(points)})
            for field, axis, points in (
                (fields.PROBE_HEIGHT, "H", scene.probes.height),
                (fields.PROBE_PRESSURE, "K", scene.probes.pressure),
            )
            if points
        ]
        return [fields.TIME.dataset(), *fluid_datasets(counts.total, counts.dim), *probes], {
            fields.FLUID_KIND.path: counts.total
        }
    sectors = sector_count(root_layout(scene).margin_sectors(), 0)
    if scene.tentacle_count > 0:
        own = _tentacle_datasets(scene, sectors)
    else:
        own = [fields.TIME.dataset(), fields.BELL_MARGIN.dataset(R=sectors)]
    bell = counts.bell
    springs = _spring_count(scene, bell)
    water_and_tank = counts.total - bell
    datasets = [
        *own,
        fields.BELL_POSITION.dataset(B=bell),
        fields.BELL_VELOCITY.dataset(B=bell),
        fields.BELL_SURFACE_VERTICES.dataset(V=2 + (2 * MESH_RINGS - 1) * sectors),
        fields.BELL_CENTRE.dataset(),
        fields.BELL_CONTRACTION.dataset(),
        fields.BELL_ACTIVATION.dataset(),
        *fluid_datasets(water_and_tank, 3, np.float32),
    ]
    static = {
        fields.FLUID_KIND.path: water_and_tank,
        fields.BELL_SURFACE_FACES.path: bell_faces(sectors).nbytes,
        fields.BELL_SPRINGS.path: springs * 2 * LONG,
        fields.BELL_MUSCLE.path: springs,
        fields.BELL_REST_POSITION.path: bell * 3 * FLOAT,
    }
    if scene.tentacle_count > 0:
        static |= _tentacle_static(scene)
    return datasets, static


def _spring_count(scene: Scene, bell: int) -> int:
    """The bell's springs: half its particles' neighbours within bell.spring_radius in a flat
    slab of cubic-lattice cells as many layers thick as the shell (n = w / l0, at least 1),
    where a neighbour |dz| layers across the slab is there for n - |dz| of its n layers. At
    2.4 l0 a slab two layers thick keeps 33 of the 56 neighbours, six layers 48.3; the presets'
    curved shells keep 27-28 (moon-jelly, moon-jelly-real-size) and 46.2 (moon-jelly-fine)."""
    b = scene.bell
    layers = max(1, round(b.thickness * b.height / scene.fluid.spacing))
    reach = math.ceil(b.spring_radius)
    axis = np.arange(-reach, reach + 1)
    dx, dy, dz = np.meshgrid(axis, axis, axis, indexing="ij")
    squared = dx**2 + dy**2 + dz**2
    # the neighbours of lattice_reference: 0 < r < spring_radius, whatever the round-off
    across = np.abs(dz[(squared > 0) & (squared < (b.spring_radius - 1e-9) ** 2)])
    neighbours = np.maximum(layers - across, 0).sum() / layers
    return round(0.5 * bell * neighbours)


def _result_bytes(datasets: list[Dataset], static: dict[str, int], frames: int) -> int:
    """``result.h5``: each per-frame dataset in whole chunks, the static ones, and HDF5's own
    records (object headers, chunk indices, attributes: a few KiB a dataset)."""
    per_frame = sum(
        math.ceil(frames / chunk_rows(spec)) * chunk_rows(spec) * frame_bytes(spec)
        for spec in datasets
    )
    return per_frame + sum(static.values()) + 4096 * (len(datasets) + len(static) + 4)


# XDMF text per frame and per per-frame array it names (a hyperslab of points or of a point
# array, with its grid's share): measured on the presets' results, 500-700 bytes.
SIDECAR_BYTES_PER_ARRAY = 650


def _sidecar_bytes(datasets: list[Dataset], frames: int) -> int:
    """``result.xdmf`` (:mod:`jellysim.io.xdmf`): a grid a frame for each part, naming the
    per-frame arrays (all but those of one number a frame), and the tentacles' connectivity
    written out once (each particle's index, as text)."""
    arrays = sum(1 for spec in datasets if spec.frame_shape)
    particles = sum(
        int(np.prod(spec.frame_shape[:2]))
        for spec in datasets
        if spec.path == fields.TENTACLE_POSITION.path
    )
    return frames * arrays * SIDECAR_BYTES_PER_ARRAY + _index_text_bytes(particles) + 2048


def _index_text_bytes(count: int) -> int:
    """The characters of ``0 1 2 ... count-1`` and a space after each."""
    total, digits, low = 0, 1, 0
    while low < count:
        high = min(count, 10**digits)
        total += (high - low) * (digits + 1)
        low, digits = high, digits + 1
    return total


# ------------------------------------------------------------------------------------- memory


def _fluid_memory(scene: Scene, plan: FluidPlan, counts: Particles) -> dict[str, int]:
    """The MPS fluid's arrays at their peak, in the middle of a pressure solve (bytes by part)."""
    p = plan.params
    n, dim = counts.total, counts.dim
    solid = counts.fluid + counts.wetted  # rows of the list at r* and of the PPE
    start_rows = counts.fluid + counts.walls if p.source == "mixed" else counts.fluid
    k = _neighbours(p, p.neighbour_radius)
    entry = INDEX + FLOAT
    lists = (start_rows + solid) * k * entry + 2 * (n + 1) * LONG
    near = max(p.re_number_density, p.re_gradient)  # one list cut to it at a time (.near)
    if near < p.neighbour_radius:
        lists += max(start_rows, solid) * _neighbours(p, near) * entry + (n + 1) * LONG
    if p.neighbour_skin > 0.0:  # the Verlet list and a float a candidate (filter_with_near)
        lists += solid * _neighbours(p, p.neighbour_radius + p.neighbour_skin) * (entry + FLOAT)
    # a wall's dummy neighbours (about half of them) have no entry in its row
    nonzeros = (counts.fluid + 0.5 * counts.wetted) * (1 + _neighbours(p, p.laplacian_radius))
    orders = 1 if p.solver == "deflated" else 2  # neighbour order, and sorted for IC(0)
    # + row pointers, diagonal, rhs ...; with fluid.matrix_precision "single" 4-byte values and
    # the diagonal's doubles apart
    single = p.matrix_precision == "single"
    value = SINGLE if single else FLOAT
    matrix = nonzeros * (INDEX + value) * orders + solid * (6 + single) * FLOAT
    if p.solver == "iccg":
        # the factor in the matrix's pattern, its compact triangles, a dense row, CG's vectors
        solver = nonzeros * (FLOAT + entry) + solid * 6 * FLOAT
    elif p.solver == "cg":
        solver = solid * 5 * FLOAT
    else:
        aggregate = p.coarse_cell**dim / SITE_VOLUME[p.lattice]  # rows per aggregate
        m = max(solid / aggregate, 1.0)
        reach = (p.coarse_cell + 2 * p.laplacian_radius) ** dim / SITE_VOLUME[p.lattice]
        fill = LU_FILL * (m * math.log(m + 1.0) if dim == 2 else m**1.45)
        threads = numba.get_num_threads()
        solver = int(m * reach * 2 * LONG + fill * entry + (threads + 9) * solid * FLOAT)
    return {
        "MPS particles": n * (STATE_BYTES[0] * dim * FLOAT + STATE_BYTES[1]),
        "neighbour lists": int(lists),
        "cell grid": n * GRID_BYTES_PER_PARTICLE + _cells(scene, p) * 2 * LONG,
        "Poisson matrix": int(matrix),
        "pressure solver": int(solver),
        "checkpoint copy": _fluid_checkpoint(p, counts),
    }


# The GPU path's arrays (jellysim.fluid.gpu.GPUSolver) per particle: five (N, D) float arrays
# (position, velocity, their step copies, the start positions), twelve (N,) float vectors
# (pressure, the two number densities, the PPE's diagonal, its inverse and right-hand side, the
# CG's five vectors, the lowest neighbour pressure), the cell and member order (int64), the
# within-radius count (int32) and six flags of a byte; the neighbour lists slot-major, each slot
# an int32 index, a float distance and a float PPE coefficient.
GPU_STATE_BYTES = (5, 12 * FLOAT + 2 * LONG + INDEX + 6)
GPU_SLOT_BYTES = INDEX + 2 * FLOAT
# The bell's springs on the GPU, per spring: the pair (int64 x 2), rest length, muscle share, the
# two adjacency entries (int64 and a float sign each), tension and normal (3 floats each), the
# muscle's two scalars.
GPU_SPRING_BYTES = 2 * LONG + 2 * FLOAT + 2 * (LONG + FLOAT) + 6 * FLOAT + 2 * FLOAT


def gpu_step_seconds(scene: Scene, plan: FluidPlan, counts: Particles) -> float:
    """The wall time of one MPS step on the GPU (s): :data:`GPU_SECONDS_PER_STEP` plus
    :data:`GPU_SECONDS_PER_SLOT` a slot of the neighbour lists at their first width, and with a
    soft bell :data:`GPU_SECONDS_PER_BELL_STEP` plus :data:`GPU_SECONDS_PER_SPRING_STEP` a
    spring."""
    seconds = GPU_SECONDS_PER_STEP + GPU_SECONDS_PER_SLOT * counts.total * _gpu_width(plan, counts)
    if scene.bell.model == "mass-spring":
        springs = _spring_count(scene, counts.bell)
        seconds += GPU_SECONDS_PER_BELL_STEP + GPU_SECONDS_PER_SPRING_STEP * springs
    return seconds


def _gpu_width(plan: FluidPlan, counts: Particles) -> int:
    """The GPU's neighbour lists' first width (:data:`jellysim.fluid.gpu.WIDTH_FACTOR` times the
    lattice's neighbours within the search radius, plus 8)."""
    from jellysim.fluid.gpu import WIDTH_FACTOR

    p = plan.params
    neighbours = lattice_reference(counts.dim, p.l0, p.neighbour_radius, p.lattice).count
    return math.ceil(WIDTH_FACTOR * neighbours) + 8


def _gpu_fluid_memory(scene: Scene, plan: FluidPlan, counts: Particles) -> dict[str, int]:
    """The GPU path's device arrays (bytes by part), as :class:`jellysim.fluid.gpu.GPUSolver`
    and :class:`jellysim.bell.gpu_springs.GPUSprings` allocate them; the lists at their
    initial width (a search that finds a particle with more neighbours widens them)."""
    from jellysim.fluid.gpu import COARSE_LARGEST, COARSE_PARTICLES

    p = plan.params
    n, dim = counts.total, counts.dim
    width = _gpu_width(plan, counts)
    f = scene.fluid
    behind = (WALL_LAYERS + DUMMY_LAYERS) * p.l0
    extent = [f.tank_width] + ([f.tank_depth] if dim == 3 else []) + [f.tank_height]
    search = p.neighbour_radius * p.l0
    # cells radius / CELLS_PER_RADIUS wide over the particles' box and a radius around it;
    # aggregates are blocks of at least CELLS_PER_RADIUS^D of them
    cells = math.prod(
        int((e + 2 * behind) * CELLS_PER_RADIUS / search) + 2 * CELLS_PER_RADIUS + 1 for e in extent
    )
    coarse_cells = math.prod(int((e + 2 * behind) / search) + 3 for e in extent)
    # a slot's PPE coefficient in 4 bytes with fluid.matrix_precision "single"
    slot = GPU_SLOT_BYTES - (FLOAT - SINGLE if p.matrix_precision == "single" else 0)
    out = {
        "GPU: MPS particles": n * (GPU_STATE_BYTES[0] * dim * FLOAT + GPU_STATE_BYTES[1]),
        "GPU: neighbour lists": n * (width * slot + INDEX),
        "GPU: cell grid": cells * 3 * INDEX + n * dim * FLOAT,  # members' coordinates too
    }
    if p.solver == "deflated":  # E^-1 dense, with the aggregates' map over the cells
        m = min(COARSE_LARGEST, max(1, n // COARSE_PARTICLES))
        out["GPU: coarse space"] = m * m * FLOAT + coarse_cells * (INDEX + FLOAT) + m * 40 * FLOAT
    if scene.bell.model == "mass-spring":
        springs = _spring_count(scene, counts.bell)
        bell = springs * GPU_SPRING_BYTES + n * dim * FLOAT
        if scene.bell.spring_integration == "implicit":
            degree = lattice_reference(3, 1.0, scene.bell.spring_radius, "square").count
            rows = 3 * counts.bell
            bell += rows * ((2 + 3 * degree) * (INDEX + FLOAT) + INDEX + 8 * FLOAT)
        out["GPU: bell springs"] = bell
    return out


def _cells(scene: Scene, params: MPSParameters) -> int:
    """The cells of a neighbour search: ``radius / CELLS_PER_RADIUS`` wide over the tank with
    its walls and dummies."""
    f, l0 = scene.fluid, params.l0
    behind = (WALL_LAYERS + DUMMY_LAYERS) * l0
    extent = [f.tank_width + 2 * behind] + ([f.tank_depth + 2 * behind] if params.dim == 3 else [])
    extent.append(f.tank_height + behind)
    side = params.neighbour_radius * l0 / CELLS_PER_RADIUS
    return math.prod(int(e / side) + 1 for e in extent)


def _fluid_checkpoint(params: MPSParameters, counts: Particles) -> int:
    """The solver's state arrays (copies): position, velocity, pressure, number density, alive,
    kind, and with a Verlet skin the reference positions and live set."""
    per_particle = 2 * counts.dim * FLOAT + 2 * FLOAT + 2
    if params.neighbour_skin > 0.0:
        per_particle += counts.dim * FLOAT + 1
    return counts.total * per_particle


def _bell_memory(scene: Scene, counts: Particles) -> dict[str, int]:
    """The soft bell's springs (pairs, rest lengths, adjacency, tensions) and skin weights."""
    springs = _spring_count(scene, counts.bell)
    vertices = 2 + (2 * MESH_RINGS - 1) * sector_count(root_layout(scene).margin_sectors(), 0)
    skin = vertices * lattice_reference(3, 1.0, SKIN_RADIUS, "square").count * 3 * FLOAT
    return {"bell springs and skin": springs * 12 * FLOAT + counts.bell * 20 * FLOAT + skin}


def _tentacle_memory(scene: Scene, plan: SubstepPlan) -> int:
    """The chains' state, model, per-thread saddle-point workspace and per-frame root and flow
    samples (the checkpoint saves the state arrays themselves)."""
    t = scene.tentacles
    particles = t.count * t.particles
    threads = min(numba.get_num_threads(), t.count)
    workspace = KKT_BLOCK * t.particles * (KKT_HALF_BANDWIDTH + 3) + 7 * 3 * t.particles
    samples = plan.substeps * t.count * 3 * 6  # roots, velocities, directions, axis, flow, noise
    return (2 * particles * 3 + 9 * t.particles + threads * workspace + samples) * FLOAT


def _writer_memory(datasets: list[Dataset], frames: int, frame_seconds: float) -> int:
    """The writer's buffered frames, the largest dataset's batch stacked for the write, the
    frame's values and HDF5's chunk caches. Frames are buffered until :data:`BATCH_FRAMES` or
    :data:`BATCH_SECONDS` have passed, on a machine up to :data:`FASTER_MACHINE` times faster
    than the time estimate's."""
    frame = sum(frame_bytes(spec) for spec in datasets)
    largest = max(frame_bytes(spec) for spec in datasets)
    batch = 1 + math.ceil(FASTER_MACHINE * BATCH_SECONDS / max(frame_seconds, 1e-9))
    buffered = min(BATCH_FRAMES, frames, batch)
    caches = sum(min(chunk_rows(spec) * frame_bytes(spec), CHUNK_CACHE_BYTES) for spec in datasets)
    return buffered * (frame + largest) + frame + caches


# --------------------------------------------------------------------------------- the estimate


def estimate(scene: Scene) -> Costs:
    """The scene's run's memory, disk and time (:class:`Costs`), from the scene alone.

    Raises InputError when the fluid or the tentacles would need more substeps a frame than
    their caps allow."""
    tentacle_plans, _ = _tentacle_plans(scene)
    frames = scene.frame_count
    memory: dict[str, int] = {}
    checkpoint = 0
    frame_seconds = FRAME_SECONDS
    plan: list[str] = []
    gpu_memory: dict[str, int] = {}
    start_seconds = 0.0
    if scene.fluid.model == "mps":
        counts = particle_counts(scene)
        fluid = fluid_plan(scene, counts)
        memory.update(_fluid_memory(scene, fluid, counts))
        checkpoint += memory["checkpoint copy"]
        if scene.bell.model == "mass-spring":
            memory.update(_bell_memory(scene, counts))
        if scene.fluid.device == "cuda":
            # the solver's arrays live on the GPU; the host keeps the state's frame copies
            for part in ("neighbour lists", "cell grid", "Poisson matrix", "pressure solver"):
                del memory[part]
            gpu_memory = _gpu_fluid_memory(scene, fluid, counts)
            step = gpu_step_seconds(scene, fluid, counts)
            start_seconds = GPU_START_SECONDS
        else:
            step = counts.fluid * FLUID_SECONDS_PER_PARTICLE_STEP
        frame_seconds += fluid.steps * step
        where = " on the GPU" if scene.fluid.device == "cuda" else ""
        plan.append(
            f"{fluid.steps} MPS steps a frame of {counts.total:,} particles "
            f"({counts.fluid:,} fluid){where}"
        )
    if tentacle_plans:
        memory["tentacles"] = 0
        for index, (group, group_plan) in enumerate(zip(scene.groups, tentacle_plans, strict=True)):
            t = group.tentacles
            memory["tentacles"] += _tentacle_memory(scene.group_scene(index), group_plan)
            frame_seconds += (
                group_plan.substeps * t.count * t.particles * TENTACLE_SECONDS_PER_PARTICLE_SUBSTEP
            )
            text = (
                f"{group_plan.substeps} substeps a frame of {t.count:,} x {t.particles:,} "
                "tentacle particles"
            )
            plan.append(text if len(scene.groups) == 1 else f"{group.name}: {text}")
        # the checkpoint holds every tentacle padded to the longest chain
        particles = scene.tentacles.particles if len(scene.groups) == 1 else scene.max_particles
        checkpoint += 2 * scene.tentacle_count * particles * 3 * FLOAT
    datasets, static = planned_datasets(scene)
    memory["result buffers"] = _writer_memory(datasets, frames, frame_seconds)
    memory["run overhead"] = RUN_OVERHEAD_BYTES
    disk = {
        "result.h5": _result_bytes(datasets, static, frames),
        "result.xdmf": _sidecar_bytes(datasets, frames),
        # the next checkpoint is written beside the last before it replaces it
        "checkpoints": 2 * checkpoint if frames - 1 > scene.solver.checkpoint_every else 0,
        "scene.toml": len(scene_to_toml(scene).encode()),
    }
    seconds = start_seconds + (frames - 1) * frame_seconds
    return Costs(memory, disk, seconds, frames, "; ".join(plan), gpu_memory)


# --------------------------------------------------------------------------- the machine's limits


def available_memory() -> int:
    """Bytes of memory this process can still have: the kernel's MemAvailable (or the free
    pages where /proc/meminfo is missing), less where a cgroup's limit is lower."""
    available = None
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                available = int(line.split()[1]) * 1024
    except OSError:
        pass
    if available is None:
        available = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    try:  # cgroup v2: the limit less what the group already uses
        group = Path("/sys/fs/cgroup")
        limit = (group / "memory.max").read_text().strip()
        if limit != "max":
            available = min(available, int(limit) - int((group / "memory.current").read_text()))
    except (OSError, ValueError):
        pass
    return available


def free_disk(folder: Path) -> int:
    """Bytes free on the file system that holds ``folder`` (or its nearest existing parent)."""
    folder = folder.absolute()
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return shutil.disk_usage(folder).free


def check_costs(
    scene: Scene,
    folder: Path | None = None,
    *,
    reclaimed: int = 0,
    quiet: bool = True,
    enforce: bool = True,
) -> Costs:
    """Estimate the scene's run and, with ``enforce``, refuse it (InputError, exit 2) before
    anything is allocated when its memory exceeds what the machine has available, its GPU
    memory (fluid.device = "cuda") what the GPU has free, or, for a run
    writing to ``folder``, its disk exceeds the space free there plus ``reclaimed`` (bytes of a
    result the run replaces or continues). A run writing to ``folder`` logs the estimate in one
    line, as a warning when it exceeds :data:`LONG_RUN_SECONDS` unless ``quiet``. The substep caps
    of :func:`estimate` hold whatever ``enforce``."""
    costs = estimate(scene)
    memory = available_memory()
    if enforce and costs.memory_bytes > memory:
        part = max(costs.memory, key=costs.memory.__getitem__)
        raise InputError(
            f"the run would need about {size(costs.memory_bytes)} of memory ({part} "
            f"{size(costs.memory[part])}), more than the {size(memory)} available; make the "
            "scene smaller (fluid.spacing, tentacles.count or tentacles.particles), or pass "
            "--no-estimate-check if the estimate is wrong"
        )
    if enforce and costs.gpu_memory:
        from jellysim.fluid.gpu import free_memory

        gpu = free_memory()
        if gpu is not None and costs.gpu_memory_bytes > gpu[0]:
            part = max(costs.gpu_memory, key=costs.gpu_memory.__getitem__)
            raise InputError(
                f"the run would need about {size(costs.gpu_memory_bytes)} on the GPU ({part} "
                f"{size(costs.gpu_memory[part])}), more than the {size(gpu[0])} free on "
                f"{gpu[1]}; make the scene smaller (fluid.spacing), free the GPU, or set "
                "fluid.device = 'cpu' (or pass --no-estimate-check if the estimate is wrong)"
            )
    if folder is None:
        return costs
    free = free_disk(folder) + reclaimed
    if enforce and costs.disk_bytes > free:
        raise InputError(
            f"the run would write about {size(costs.disk_bytes)} ({costs.frames:,} frames), "
            f"more than the {size(free)} free for '{folder}'; lower duration or fps, or pass "
            "--no-estimate-check if the estimate is wrong"
        )
    long_run = costs.seconds > LONG_RUN_SECONDS and not quiet
    log.log(logging.WARNING if long_run else logging.INFO, "%s", costs.describe())
    return costs


__all__ = [
    "FLUID_SECONDS_PER_PARTICLE_STEP",
    "GPU_SECONDS_PER_BELL_STEP",
    "GPU_SECONDS_PER_SLOT",
    "GPU_SECONDS_PER_SPRING_STEP",
    "GPU_SECONDS_PER_STEP",
    "GPU_START_SECONDS",
    "gpu_step_seconds",
    "LONG_RUN_SECONDS",
    "TENTACLE_SECONDS_PER_PARTICLE_SUBSTEP",
    "Costs",
    "Particles",
    "available_memory",
    "check_costs",
    "estimate",
    "free_disk",
    "particle_counts",
    "planned_datasets",
]
