"""Initial particle arrangements for MPS on a square (2-D) or cubic (3-D) lattice of spacing l0,
on the hexagonal (triangular) lattice of spacing l0 in 2-D, or on the face-centred cubic lattice
of nearest-neighbour distance l0 in 3-D.

Cell-centred convention: space is cut into cells of side l0 with faces on the planes ``i l0``, and
every particle sits at a cell centre ``(i + 1/2) l0``, standing for that cell's volume. The inner
faces of a tank are cell faces: left inner wall at x = 0, floor at y = 0 (2-D, y up) or z = 0
(3-D, z up; the tank spans x in [0, width], y in [0, depth]). Wall particles fill the cells just
outside those faces (the first wall layer is centred half a spacing behind the face), dummy
particles the cells beyond. A water block ``[x0, x1]`` takes the cells whose centres lie inside
it: a block of width ``a`` from a wall holds ``a / l0`` particles across, its water fills exactly
``[0, a]``, and it never overlaps a wall.

Hexagonal lattice (``lattice="hexagonal"``, 2-D): horizontal rows ``h = (sqrt(3)/2) l0`` apart,
row j centred at ``y = (j + 1/2) h``, its particles at ``x = (i + 1/4) l0`` (j even) or
``(i + 3/4) l0`` (j odd), so that every particle has six neighbours at l0 and each row of a tank
whose width is a whole number of l0 holds width / l0 particles, l0 / 4 left (j even) or right
(j odd) of the middle. Side walls and dummies are the lattice's own sites behind the faces (the
wall is a zigzag of amplitude l0 / 2: a site less than l0 behind a side face is a wall, the next
2 l0 dummies; behind the floor one row of walls and two of dummies). A block of width ``a``
again holds ``a / l0`` particles a row and a height ``H`` the ``round(H / h)`` rows whose
centres lie below it (:func:`filled_height`), for blocks whose sides are whole numbers of l0
from the walls (as in every scene).
Why this lattice: docs/theory/fluid.md, "The lattice".

Face-centred cubic lattice (``lattice="fcc"``, 3-D), the hexagonal lattice's analogue in 3-D,
with its close-packed (111) planes horizontal: layers ``h_z = sqrt(2/3) l0`` apart, layer k
centred at ``z = (k + 1/2) h_z``, each a hexagonal lattice of spacing l0 with rows along x,
``h_y = (sqrt(3)/2) l0`` apart; layer k is shifted by a third of the triangle against the layer
below (ABC stacking). The site (i, j, k) is at ``x = (i + (j + k)/2 + 1/4) l0``,
``y = (j + k/3 + 1/6) h_y``, ``z = (k + 1/2) h_z``: every site has twelve neighbours at l0, a row
of a block whose width is a whole number of l0 holds width / l0 sites (l0 / 4 left or right of
the middle), and the rows nearest a y face lie 1/6, 1/2 or 5/6 of h_y inside it, by layer. The
tank's walls and dummies are the lattice's own sites behind its faces: a site less than l0
behind a face (the larger of its distances behind the faces it is behind) is a wall, one less
than 3 l0 behind a dummy (one layer of walls and three of dummies under the floor). A water block
takes the sites whose centres lie inside it; its height is the ``round(H / h_z)`` layers centred
below H (:func:`filled_height`).
"""

from __future__ import annotations

import numpy as np

FLUID, WALL, DUMMY = 0, 1, 2  # particle kinds (stored as int8)
LATTICES = ("square", "hexagonal", "fcc")
# vertical spacing of the rows (2-D) or layers (3-D) over l0
ROW_HEIGHT = {"square": 1.0, "hexagonal": 0.5 * np.sqrt(3.0), "fcc": np.sqrt(2.0 / 3.0)}
# the area (2-D) or volume (3-D) each site stands for, over l0^D: the row spacing of the
# hexagonal lattice, the row and layer spacings of the fcc one
SITE_VOLUME = {"square": 1.0, "hexagonal": 0.5 * np.sqrt(3.0), "fcc": np.sqrt(0.5)}
WALL_LAYERS, DUMMY_LAYERS = 1, 2  # a tank's layers of wall and dummy particles behind its faces
DIMENSIONS = {"hexagonal": 2, "fcc": 3}  # lattices that exist in one dimension only

_TOLERANCE = 1e-9  # in l0: cell centres on a block's boundary count as inside


def _cells(length: float, l0: float) -> int:
    """The whole number of spacings ``l0`` in ``length``, within the scene check's tolerance
    (config/load.py: 1e-6 of the count, so a spacing typed to six or seven figures, 0.0536667
    for 0.161 / 3, is taken as meant)."""
    count = round(length / l0)
    if count < 1 or abs(length / l0 - count) > 1e-6 * max(1.0, count):
        raise ValueError(f"length {length} is not a whole number of spacings l0 = {l0}")
    return count


def tank(
    inner_width: float,
    inner_height: float,
    l0: float,
    dim: int = 2,
    inner_depth: float | None = None,
    wall_layers: int = WALL_LAYERS,
    dummy_layers: int = DUMMY_LAYERS,
    lattice: str = "square",
) -> tuple[np.ndarray, np.ndarray]:
    """An open-top tank: ``(positions (N, dim) m float64, kinds (N,) int8)``.

    Wall particles fill the ``wall_layers`` layers of cells outside the inner faces, dummy
    particles the next ``dummy_layers`` layers. Corners are filled. The side walls rise from the
    floor to ``inner_height`` (their top cell's centre is half a spacing below it). ``inner_width``,
    ``inner_height`` (and ``inner_depth`` in 3-D) must be whole multiples of l0 (on the hexagonal
    lattice the walls rise to the last row centred below ``inner_height``, which is not checked).
    ``lattice``: "square" (cubic in 3-D), "hexagonal" (2-D only) or "fcc" (3-D only; the
    module's docstring: there ``wall_layers`` and ``dummy_layers`` count l0 behind the faces).
    """
    if dim not in (2, 3):
        raise ValueError(f"dim must be 2 or 3, not {dim}")
    check_lattice(lattice, dim)
    if lattice == "hexagonal":
        return _hexagonal_tank(inner_width, inner_height, l0, wall_layers, dummy_layers)
    if lattice == "fcc":
        if inner_depth is None:
            raise ValueError("a 3-D tank needs inner_depth")
        return _fcc_tank(
            (_cells(inner_width, l0) * l0, inner_depth), inner_height, l0, wall_layers, dummy_layers
        )
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
    lattice: str = "square",
) -> np.ndarray:
    """Fluid positions ``(N, dim)`` m: the cell centres ``(i + 1/2) l0`` inside the box
    ``[x0, x1] x [y0, y1]`` (``x [z0, z1]`` in 3-D, when z0 and z1 are given). The last
    coordinate is up. On the ``"hexagonal"`` (2-D) or ``"fcc"`` (3-D) lattice, its sites inside
    the box."""
    check_lattice(lattice, 2 if z0 is None or z1 is None else 3)
    if lattice == "hexagonal":
        return _hexagonal_block(x0, x1, y0, y1, l0)
    if lattice == "fcc" and z0 is not None and z1 is not None:
        sites = _fcc_sites(np.array([x0, y0, z0]), np.array([x1, y1, z1]), l0)
        return sites[_inside(sites, np.array([x0, y0, z0]), np.array([x1, y1, z1]), l0)]
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


def box_obstacle(
    lower: np.ndarray, upper: np.ndarray, l0: float, lattice: str = "square"
) -> tuple[np.ndarray, np.ndarray]:
    """A solid box in a 3-D tank: ``(positions (N, 3) m float64, kinds (N,) int8)``.

    The lattice's sites inside the box ``[lower, upper]`` (corners in m, the sites a water block
    of that box would take, :func:`water_block`): those less than ``l0`` inside its nearest
    face are wall particles, the deeper ones dummies, as behind the tank's faces. A box standing
    on the floor (``lower[2] <= 0``) has no wall layer along its bottom: the floor's walls are
    there. Each side should be at least ``2 l0`` (the scene checks it).
    """
    lower, upper = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    sites = water_block(
        lower[0], upper[0], lower[1], upper[1], l0, max(lower[2], 0.0), upper[2], lattice
    )
    depths = np.concatenate([sites - lower, upper - sites], axis=1)
    if lower[2] <= _TOLERANCE * l0:
        depths[:, 2] = np.inf  # the bottom face lies on the floor
    depth = depths.min(axis=1)
    kinds = np.where(depth < l0 * (1.0 - _TOLERANCE), WALL, DUMMY).astype(np.int8)
    return sites, kinds


def filled_height(height: float, l0: float, lattice: str = "square") -> float:
    """The height (m) that a block from the floor to ``height`` fills on the lattice: its rows
    (those whose centres lie below ``height``) times the row spacing; on the square lattice
    ``height`` itself (a whole number of l0, checked by the scene)."""
    if lattice == "square":
        return height
    row = ROW_HEIGHT[lattice] * l0
    return _rows_below(height, row) * row


def check_lattice(lattice: str, dim: int) -> None:
    """Raise ValueError unless ``lattice`` is one of LATTICES and exists in ``dim`` dimensions."""
    if lattice not in LATTICES:
        raise ValueError(f"lattice = {lattice!r}; allowed: {', '.join(LATTICES)}")
    if DIMENSIONS.get(lattice, dim) != dim:
        raise ValueError(f"the {lattice} lattice is {DIMENSIONS[lattice]}-D only")


def _rows_below(height: float, row: float) -> int:
    """The number of rows j >= 0 centred at (j + 1/2) row at or below ``height``."""
    return max(0, int(np.floor(height / row - 0.5 + _TOLERANCE)) + 1)


def _hexagonal_sites(columns: tuple[int, int], rows: tuple[int, int], l0: float) -> np.ndarray:
    """Sites (i, j) of the hexagonal lattice for i, j in the half-open ranges, as (N, 2) m."""
    grid_i, grid_j = np.meshgrid(np.arange(*columns), np.arange(*rows), indexing="ij")
    i, j = grid_i.ravel(), grid_j.ravel()
    x = (i + np.where(j % 2 == 0, 0.25, 0.75)) * l0
    y = (j + 0.5) * (ROW_HEIGHT["hexagonal"] * l0)
    return np.column_stack([x, y])


def _hexagonal_tank(
    inner_width: float, inner_height: float, l0: float, wall_layers: int, dummy_layers: int
) -> tuple[np.ndarray, np.ndarray]:
    layers = wall_layers + dummy_layers
    n = _cells(inner_width, l0)
    top = _rows_below(inner_height, ROW_HEIGHT["hexagonal"] * l0)
    sites = _hexagonal_sites((-layers - 1, n + layers + 1), (-layers, top), l0)
    x = sites[:, 0] / l0
    j = np.rint(sites[:, 1] / (ROW_HEIGHT["hexagonal"] * l0) - 0.5).astype(np.int64)
    behind_side = np.maximum(-x, x - n)  # l0 behind the nearer side face (< 0: inside)
    layer = np.where(behind_side > 0.0, np.floor(behind_side), -1)
    layer = np.maximum(layer, -j - 1)  # rows below the floor
    keep = (layer >= 0) & (layer < layers)
    kinds = np.where(layer[keep] < wall_layers, WALL, DUMMY).astype(np.int8)
    return sites[keep], kinds


def _hexagonal_block(x0: float, x1: float, y0: float, y1: float, l0: float) -> np.ndarray:
    row = ROW_HEIGHT["hexagonal"] * l0
    first_row = int(np.ceil(y0 / row - 0.5 - _TOLERANCE))
    last_row = int(np.floor(y1 / row - 0.5 + _TOLERANCE))
    first = int(np.floor(x0 / l0)) - 1
    last = int(np.ceil(x1 / l0)) + 1
    sites = _hexagonal_sites((first, last + 1), (first_row, last_row + 1), l0)
    x = sites[:, 0]
    inside = (x >= x0 - _TOLERANCE * l0) & (x <= x1 + _TOLERANCE * l0)
    return sites[inside]


def _inside(sites: np.ndarray, lower: np.ndarray, upper: np.ndarray, l0: float) -> np.ndarray:
    """Sites whose centres lie in the box (centres on its boundary count as inside)."""
    tolerance = _TOLERANCE * l0
    return np.all((sites >= lower - tolerance) & (sites <= upper + tolerance), axis=1)


def _fcc_sites(lower: np.ndarray, upper: np.ndarray, l0: float) -> np.ndarray:
    """Sites of the face-centred cubic lattice (the module's docstring) in the box, as (N, 3) m,
    layer by layer."""
    row, layer = ROW_HEIGHT["hexagonal"] * l0, ROW_HEIGHT["fcc"] * l0
    out = []
    for k in range(int(np.floor(lower[2] / layer - 0.5)), int(np.ceil(upper[2] / layer)) + 1):
        z = (k + 0.5) * layer
        if not lower[2] - _TOLERANCE * l0 <= z <= upper[2] + _TOLERANCE * l0:
            continue
        shift = k / 3.0 + 1.0 / 6.0
        rows = np.arange(int(np.floor(lower[1] / row - shift)), int(np.ceil(upper[1] / row)) + 1)
        columns = np.arange(int(np.floor(lower[0] / l0)) - 1, int(np.ceil(upper[0] / l0)) + 2)
        i, j = (a.ravel() for a in np.meshgrid(columns, rows, indexing="ij"))
        x = (
            i + 0.5 * ((j + k) % 2) + 0.25
        ) * l0  # i counts whole l0 (the (i, j, k) above, re-indexed)
        keep = (x >= lower[0] - _TOLERANCE * l0) & (x <= upper[0] + _TOLERANCE * l0)
        out.append(np.column_stack([x[keep], (j[keep] + shift) * row, np.full(keep.sum(), z)]))
    return np.concatenate(out) if out else np.empty((0, 3))


def _fcc_tank(
    inner: tuple[float, float],
    inner_height: float,
    l0: float,
    wall_layers: int,
    dummy_layers: int,
) -> tuple[np.ndarray, np.ndarray]:
    thickness = (wall_layers + dummy_layers) * l0
    width, depth = inner
    lower = np.array([-thickness, -thickness, -thickness])
    upper = np.array([width + thickness, depth + thickness, inner_height])
    sites = _fcc_sites(lower, upper, l0)
    x, y, z = sites.T
    behind = np.max(np.column_stack([-x, x - width, -y, y - depth, -z]), axis=1)
    keep = (behind > _TOLERANCE * l0) & (behind < thickness - _TOLERANCE * l0)
    kinds = np.where(behind[keep] < wall_layers * l0, WALL, DUMMY).astype(np.int8)
    return sites[keep], kinds
