"""Initial particle arrangements for MPS on a square (2-D) or cubic (3-D) lattice of spacing l0.

Cell-centred convention: space is cut into cells of side l0 with faces on the planes ``i l0``, and
every particle sits at a cell centre ``(i + 1/2) l0``, standing for that cell's volume. The inner
faces of a tank are cell faces: left inner wall at x = 0, floor at y = 0 (2-D, y up) or z = 0
(3-D, z up; the tank spans x in [0, width], y in [0, depth]). Wall particles fill the cells just
outside those faces (the first wall layer is centred half a spacing behind the face), dummy
particles the cells beyond. A water block ``[x0, x1]`` takes the cells whose centres lie inside
it: a block of width ``a`` from a wall holds ``a / l0`` particles across, its water fills exactly
``[0, a]``, and it never overlaps a wall.
"""

from __future__ import annotations

import numpy as np

FLUID, WALL, DUMMY = 0, 1, 2  # particle kinds (stored as int8)

_TOLERANCE = 1e-9  # in l0: cell centres on a block's boundary count as inside


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

    Wall particles fill the ``wall_layers`` layers of cells outside the inner faces, dummy
    particles the next ``dummy_layers`` layers. Corners are filled. The side walls rise from the
    floor to ``inner_height`` (their top cell's centre is half a spacing below it). ``inner_width``,
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
    # cell indices i: centres (i + 1/2) l0; inner cells 0..n-1 horizontally, 0.. vertically
    axes = [np.arange(-layers, n + layers) for n in horizontal]
    axes.append(np.arange(-layers, top))
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)
    # Layer behind the inner faces: 0 for the cells touching them.
    outside = -grid[:, -1] - 1
    for k, n in enumerate(horizontal):
        outside = np.maximum(outside, np.maximum(-grid[:, k] - 1, grid[:, k] - n))
    keep = outside >= 0
    kinds = np.where(outside[keep] < wall_layers, WALL, DUMMY).astype(np.int8)
    return (grid[keep].astype(np.float64) + 0.5) * l0, kinds


def water_block(
    x0: float,
    x1: float,
    y0: float,
    y1: float,
    l0: float,
    z0: float | None = None,
    z1: float | None = None,
) -> np.ndarray:
    """Fluid positions ``(N, dim)`` m: the cell centres ``(i + 1/2) l0`` inside the box
    ``[x0, x1] x [y0, y1]`` (``x [z0, z1]`` in 3-D, when z0 and z1 are given). The last
    coordinate is up."""
    bounds = [(x0, x1), (y0, y1)]
    if z0 is not None and z1 is not None:
        bounds.append((z0, z1))
    axes = []
    for lo, hi in bounds:
        first = int(np.ceil(lo / l0 - 0.5 - _TOLERANCE))
        last = int(np.floor(hi / l0 - 0.5 + _TOLERANCE))
        axes.append(np.arange(first, last + 1))
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(bounds))
    return (grid.astype(np.float64) + 0.5) * l0
