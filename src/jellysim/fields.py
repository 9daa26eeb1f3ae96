"""Every dataset of ``result.h5``, described once: path, axes, dtype, units and meaning.

A neutral module (it imports nothing of jellysim): the writers declare their datasets from these
specs, the readers (``io.result.Result``, plots, render, export, view) name what they read through
them, so the layout of DESIGN §3 is spelled in one place.

Axis names: F frames, T simulated tentacles, P particles per tentacle, R margin points,
B bell particles, V bell surface vertices, M surface triangles, S springs, N fluid particles
(water and tank), D the fluid's dimensions (2 or 3), H height probes, K pressure probes. A
field's ``axes`` are the axes of one frame (per-frame fields) or of the whole array (static
fields).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Dataset:
    """A per-frame dataset as a writer creates it: its path, the shape of one frame, units and
    element type."""

    path: str
    frame_shape: tuple[int, ...]
    units: str
    dtype: Any = np.float64
    # further attributes of the dataset (name, value), e.g. the probes' names
    attributes: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True)
class Field:
    """One dataset of the result layout.

    ``axes``: the frame's shape as axis names (see the module docstring) or fixed lengths;
    ``dtype``: the element type (a writer may store a per-frame float field as float32 where it
    says so); ``per_frame``: False for datasets written once.
    """

    path: str
    axes: tuple[str | int, ...]
    units: str
    doc: str
    dtype: Any = np.float64
    per_frame: bool = True

    def dataset(self, dtype: Any = None, **sizes: int) -> Dataset:
        """The writer's :class:`Dataset` with the axis lengths ``sizes`` (e.g. ``T=6, P=60``)."""
        missing = [a for a in self.axes if isinstance(a, str) and a not in sizes]
        if missing:
            raise ValueError(f"{self.path}: the length of axes {missing} is needed")
        shape = tuple(a if isinstance(a, int) else int(sizes[a]) for a in self.axes)
        return Dataset(self.path, shape, self.units, self.dtype if dtype is None else dtype)


TIME = Field("time", (), "s", "the frame's time")

# The tentacles (paper §4.1).
TENTACLE_POSITION = Field(
    "tentacles/position", ("T", "P", 3), "m", "simulated tentacle particles, root first"
)
TENTACLE_VELOCITY = Field("tentacles/velocity", ("T", "P", 3), "m/s", "their velocities")
TENTACLE_GROUP = Field(
    "tentacles/group",
    ("T",),
    "1",
    "the group of each simulated tentacle, an index into the attribute tentacle_groups",
    np.int32,
    False,
)
TENTACLE_PARTICLES = Field(
    "tentacles/particles",
    ("T",),
    "1",
    "particles of each simulated tentacle; its rows beyond them in position and velocity are "
    "NaN (groups of shorter chains)",
    np.int32,
    False,
)
TENTACLE_CONSTRAINT_ERROR = Field(
    "tentacles/constraint_error", (), "1", "largest relative segment-length error in the frame"
)
TENTACLE_PROJECTION_ITERATIONS = Field(
    "tentacles/projection_iterations",
    (),
    "1",
    "most length-projection iterations of a substep in the frame",
    np.int32,
)

# The bell (paper §4.2): what drove the roots, and its body.
BELL_RIM = Field("bell/rim", ("T", 3), "m", "tentacle base points (what drove the roots)")
BELL_RIM_VELOCITY = Field("bell/rim_velocity", ("T", 3), "m/s", "their velocities")
BELL_MARGIN = Field(
    "bell/margin", ("R", 3), "m", "the margin as a closed polyline (interpolated roots lie on it)"
)
BELL_POSITION = Field(
    "bell/position", ("B", 3), "m", "bell particles, or the kinematic bell's surface vertices"
)
BELL_VELOCITY = Field("bell/velocity", ("B", 3), "m/s", "bell particle velocities")
BELL_SURFACE_VERTICES = Field(
    "bell/surface_vertices",
    ("V", 3),
    "m",
    "smooth bell surface for rendering (topology bell/surface_faces)",
    np.float32,
)
BELL_CENTRE = Field("bell/centre", (3,), "m", "the bell's centre (mean of its particles)")
BELL_CONTRACTION = Field(
    "bell/contraction", (), "1", "fraction of the margin radius lost (0 relaxed)"
)
BELL_ACTIVATION = Field("bell/activation", (), "1", "muscle activation a(t) in [0, 1]")
BELL_SURFACE_FACES = Field(
    "bell/surface_faces", ("M", 3), "1", "triangles over the surface vertices", np.int32, False
)
BELL_SPRINGS = Field(
    "bell/springs", ("S", 2), "1", "bell particle pairs joined by springs", np.int64, False
)
BELL_MUSCLE = Field("bell/muscle", ("S",), "1", "springs of the circular muscle", np.bool_, False)
BELL_REST_POSITION = Field(
    "bell/rest_position", ("B", 3), "m", "bell particles at rest", np.float64, False
)

# The MPS fluid (water and tank).
FLUID_POSITION = Field("fluid/position", ("N", "D"), "m", "fluid and wall particle positions")
FLUID_VELOCITY = Field("fluid/velocity", ("N", "D"), "m/s", "their velocities")
FLUID_PRESSURE = Field("fluid/pressure", ("N",), "Pa", "pressure")
FLUID_NUMBER_DENSITY = Field("fluid/number_density", ("N",), "1", "MPS particle number density")
FLUID_ALIVE = Field(
    "fluid/alive", ("N",), "1", "False from the frame a particle left the domain", np.bool_
)
FLUID_KIND = Field("fluid/kind", ("N",), "1", "0 fluid, 1 wall, 2 dummy", np.int8, False)

# Probes of a fluid-only scene (docs/theory/fluid.md F14, F15); each with an attribute `names`.
PROBE_HEIGHT = Field("probes/height", ("H",), "m", "water depth along each height probe's line")
PROBE_PRESSURE = Field(
    "probes/pressure", ("K",), "Pa", "wall pressure at each pressure probe, the frame's mean"
)

# The pressure solver.
SOLVER_ITERATIONS = Field(
    "solver/iterations", (), "1", "pressure-solver iterations of the frame's last step", np.int32
)
SOLVER_RESIDUAL = Field("solver/residual", (), "1", "its relative residual")
SOLVER_STEPS = Field("solver/steps", (), "1", "MPS steps in the frame", np.int32)

FIELDS: tuple[Field, ...] = (
    TIME,
    TENTACLE_POSITION,
    TENTACLE_VELOCITY,
    TENTACLE_GROUP,
    TENTACLE_PARTICLES,
    TENTACLE_CONSTRAINT_ERROR,
    TENTACLE_PROJECTION_ITERATIONS,
    BELL_RIM,
    BELL_RIM_VELOCITY,
    BELL_MARGIN,
    BELL_POSITION,
    BELL_VELOCITY,
    BELL_SURFACE_VERTICES,
    BELL_CENTRE,
    BELL_CONTRACTION,
    BELL_ACTIVATION,
    BELL_SURFACE_FACES,
    BELL_SPRINGS,
    BELL_MUSCLE,
    BELL_REST_POSITION,
    FLUID_POSITION,
    FLUID_VELOCITY,
    FLUID_PRESSURE,
    FLUID_NUMBER_DENSITY,
    FLUID_ALIVE,
    FLUID_KIND,
    PROBE_HEIGHT,
    PROBE_PRESSURE,
    SOLVER_ITERATIONS,
    SOLVER_RESIDUAL,
    SOLVER_STEPS,
)
BY_PATH: dict[str, Field] = {field.path: field for field in FIELDS}
