"""Initial particle arrangements for MPS on a square (2-D) or cubic (3-D) lattice of spacing l0.

Lattice convention: every particle sits on a lattice point ``index * l0`` (integer indices). The
inner faces of a tank are lattice planes: left inner wall at x = 0, floor at y = 0 (2-D, y up) or
z = 0 (3-D, z up; the tank spans x in [0, width], y in [0, depth]). Fluid particles are the lattice
points strictly inside; a water block ``(x0, x1]`` takes the points with ``x0 < i l0 <= x1``, so a
block starting at a wall never overlaps it and holds ``round((x1 - x0) / l0)`` particles across.
Each fluid particle stands for a cell of side l0 centred on it, so the water reaches half a spacing
beyond the outermost particles (and the wall surface sits half a spacing in front of the wall
particles).
"""

from __future__ import annotations

import numpy as np

FLUID, WALL, DUMMY = 0, 1, 2  # particle kinds (stored as int8)

_TOLERANCE = 1e-9  # in l0: lattice points on a block's boundary


def _cells(length: float, l0: float) -> int:
    count = round(length / l0)
    if count < 1 or abs(count * l0 - length) > 1e-6 * l0:
        raise ValueError(f"length {length} is not a whole number of spacings l0 = {l0}")
    return count


def tank(
    inner_width: float,
    inner_height: float,
    l0: float,
    dim: int = 2,
    inner_depth: float | None = None,
    wall_layers: int = 1,
    dummy_layers: int = 2,
) -> tuple[np.ndarray, np.ndarray]:
    """An open-top tank: ``(positions (N, dim) m float64, kinds (N,) int8)``.

    Wall particles fill the ``wall_layers`` lattice layers from the inner faces outwards (the
    first on the faces themselves), dummy particles the next ``dummy_layers`` layers. Corners are
    filled. The side walls rise from the floor to ``inner_height``. ``inner_width``,
    ``inner_height`` (and ``inner_depth`` in 3-D) must be whole multiples of l0.
    """
    if dim not in (2, 3):
        raise ValueError(f"dim must be 2 or 3, not {dim}")
    layers = wall_layers + dummy_layers
    horizontal = [_cells(inner_width, l0)]
    if dim == 3:
        if inner_depth is None:
            raise ValueError("a 3-D tank needs inner_depth")
        horizontal.append(_cells(inner_depth, l0))
    top = _cells(inner_height, l0)
    axes = [np.arange(-layers, n + layers + 1) for n in horizontal]
    axes.append(np.arange(-layers, top + 1))
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)
    # Depth outside the inner region, in layers: 0 on the inner faces.
    outside = np.maximum(-grid[:, -1], 0)
    interior = grid[:, -1] >= 1
    for k, n in enumerate(horizontal):
        outside = np.maximum(outside, np.maximum(-grid[:, k], grid[:, k] - n))
        interior &= (grid[:, k] >= 1) & (grid[:, k] <= n - 1)
    keep = ~interior
    kinds = np.where(outside[keep] < wall_layers, WALL, DUMMY).astype(np.int8)
    return grid[keep].astype(np.float64) * l0, kinds


def water_block(
    x0: float,
    x1: float,
    y0: float,
    y1: float,
    l0: float,
    z0: float | None = None,
    z1: float | None = None,
) -> np.ndarray:
    """Fluid positions ``(N, dim)`` m: the lattice points with ``x0 < x <= x1``, ``y0 < y <= y1``
    (and ``z0 < z <= z1`` in 3-D, when z0 and z1 are given). The last coordinate is up."""
    bounds = [(x0, x1), (y0, y1)]
    if z0 is not None and z1 is not None:
        bounds.append((z0, z1))
    axes = []
    for lo, hi in bounds:
        first = int(np.floor(lo / l0 + _TOLERANCE)) + 1
        last = int(np.floor(hi / l0 + _TOLERANCE))
        axes.append(np.arange(first, last + 1))
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(bounds))
    return grid.astype(np.float64) * l0
