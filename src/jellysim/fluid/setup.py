"""A scene's MPS fluid: its particles on the lattice (built once) and its solver parameters."""

from __future__ import annotations

from typing import Any

import numpy as np

from jellysim.config.schema import Scene
from jellysim.fluid.geometry import FLUID, box_obstacle, filled_height, tank, water_block
from jellysim.fluid.mps import MPSParameters, MPSSolver


def fluid_particles(scene: Scene) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """The tank and its water: positions (N, D) m, kinds (N,) and the case geometry attributes
    of DESIGN §3 (left inner wall at x = 0, floor at 0 along the last axis). On the hexagonal
    and fcc lattices the height attribute is the height the water's rows or layers fill
    (:func:`filled_height`)."""
    f = scene.fluid
    dim, l0 = f.dimensions, f.spacing
    walls, kinds = tank(
        f.tank_width,
        f.tank_height,
        l0,
        dim=dim,
        inner_depth=f.tank_depth if dim == 3 else None,
        lattice=f.lattice,
    )
    width = f.water_width if f.geometry == "dam-break" else f.tank_width
    height = filled_height(f.water_height, l0, f.lattice)
    # the column against the left wall, or the right one (water_side)
    start = 0.0 if f.geometry != "dam-break" or f.water_side == "left" else f.tank_width - width
    if dim == 2:
        water = water_block(start, start + width, 0.0, f.water_height, l0, lattice=f.lattice)
    else:
        water = water_block(
            start, start + width, 0.0, f.tank_depth, l0, 0.0, f.water_height, lattice=f.lattice
        )
    solids = [(walls, kinds)]
    for box in f.obstacles:  # solid boxes, clear of the water (checked by the scene)
        solids.append(box_obstacle(np.array(box[:3]), np.array(box[3:]), l0, f.lattice))
    positions = np.concatenate([water, *(p for p, _ in solids)])
    all_kinds = np.concatenate([np.full(len(water), FLUID, dtype=np.int8), *(k for _, k in solids)])
    if f.geometry == "dam-break":
        attributes = {"column_width": width, "column_height": height}
    else:
        attributes = {"water_depth": height}
    return positions, all_kinds, attributes


def tank_corner(scene: Scene) -> np.ndarray:
    """The tank's inner upper corner (D,) m: its width, (depth,) and height; the inner lower
    corner is the origin."""
    f = scene.fluid
    if f.dimensions == 3:
        return np.array([f.tank_width, f.tank_depth, f.tank_height])
    return np.array([f.tank_width, f.tank_height])


def mps_parameters(scene: Scene) -> MPSParameters:
    """The solver's parameters from the scene's ``[fluid]`` and ``[water]`` tables."""
    f, w = scene.fluid, scene.water
    return MPSParameters(
        dim=f.dimensions,
        l0=f.spacing,
        density=w.density,
        kinematic_viscosity=w.viscosity / w.density,
        gravity=tuple(w.gravity[: f.dimensions]),
        source=f.source,
        surface=f.surface,
        gradient=f.gradient,
        surface_threshold=f.surface_threshold,
        collision_distance=f.collision_distance,
        surface_repulsion=f.surface_repulsion,
        lattice=f.lattice,
        solver=f.solver,
        matrix_precision=f.matrix_precision,
        coarse_cell=f.coarse_cell,
        neighbour_skin=f.neighbour_skin,
        tolerance=f.tolerance,
        courant=f.courant,
    )


def make_solver(
    params: MPSParameters, positions: np.ndarray, kinds: np.ndarray, device: str
) -> Any:
    """The fluid's solver on ``device`` (``fluid.device``): "cpu", :class:`MPSSolver`; "cuda",
    :class:`jellysim.fluid.gpu.GPUSolver` (imported only then, with Numba's CUDA module), or
    InputError saying what to install where no GPU can run it."""
    if device == "cuda":
        from jellysim.fluid.gpu import solver_on_gpu

        return solver_on_gpu(params, positions, kinds)
    return MPSSolver(params, positions, kinds)
