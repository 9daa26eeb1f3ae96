"""The built-in preview renderer: a PNG of one :class:`Frame` with nothing beyond NumPy and
Matplotlib (Agg), good enough to judge motion.

Every primitive (bell triangle, tentacle segment, fluid particle) becomes one polygon of a single
Matplotlib ``PolyCollection``, sorted far to near by the distance of its centre from the camera
(painter's algorithm), so tentacles and the translucent bell interleave by depth. Per frame:

- Projection: a pinhole camera, ``x = W/2 + f x_c / z_c`` and ``y = H/2 - f y_c / z_c`` (pixels,
  y down) with ``(x_c, y_c, z_c)`` the point in the camera's (right, up, forward) basis and
  ``f = (W/2) / tan(angle/2)`` the focal length in pixels (``angle`` is the horizontal field of
  view). Primitives with a corner closer than ``NEAR_FRACTION`` of the camera's distance to its
  ``look_at`` point, or behind the camera, are dropped, as are those wholly outside the image.
- Background: the first jellyfish's ``water_color`` at the top of the image, fading linearly to
  ``BOTTOM_DARKENING`` times it at the bottom.
- Bell: flat-coloured triangles, Lambert shading of the face's mean vertex normal (two-sided: the
  normal is turned towards the camera) plus ``AMBIENT``, lit by a key light from above and from
  the camera's side (``KEY_LIGHT_UP``, ``KEY_LIGHT_BACK``); colour and opacity from the shared
  materials (:mod:`jellysim.render.materials`): ``1 - bell_transparency`` opaque, clearer
  face-on and opaque and lighter at the silhouette (``rim``), with ``stripes`` radial stripes.
- Tentacles: opaque ribbons of quadrilaterals, one per segment, whose half-width at each
  particle is the radius from :func:`tentacle_radii` projected at its depth (``r f / z_c``, at
  least ``MIN_HALF_WIDTH``), in the tentacle's face-on colour (``tentacle_transparency``), lit
  as thin cylinders: brightness ``TENTACLE_AMBIENT +
  (1 - TENTACLE_AMBIENT) sin a`` with ``a`` the angle between the segment and the key light.
- Tentacle groups: each group in its own look (:func:`~jellysim.render.materials.group_look`);
  a ribbon group's oral arms as the triangles of the meshes POV-Ray draws, shaded as the bell
  (:func:`~jellysim.render.ribbons.ribbon_primitives`), the manubrium as a cone's triangles.
- Gonads (``look.gonads``): the horseshoes' tubes drawn as tentacles are, in
  ``look.gonad_color``, untapered and opaque, sorted among the bell's triangles.
- Fluid particles: translucent hexagons of radius ``fluid_radius`` projected (at least
  ``MIN_HALF_WIDTH``), in the water colour moved ``FLUID_TINT`` of the way to white.
- Depth fade (exponential fog): a colour at distance ``d`` from the camera keeps the fraction
  ``exp(-max(d - d_front, 0) / fog_length)`` of its contrast against the background colour of its
  image row, so far things dissolve into the water behind them. The scale comes from the scene
  extent ``E``, the diagonal of the bounding box of the bells and tentacles in front of the camera:
  ``fog_length = FOG_EXTENTS E`` and ``d_front = |look_at - location| - E/2``, the front of a
  scene centred on ``look_at``. The near side of a jellyfish centred there is unfogged, its far
  side keeps about 60 % of its contrast, and one swimming away from a fixed camera fades out.

Colours are linear RGB (as in :class:`Look`); shading and fog are computed in linear RGB and the
result is encoded to sRGB for the PNG, like POV-Ray with ``assumed_gamma 1``. Agg blends the
translucent polygons in sRGB, an approximation a preview can afford.

Quality by name (:data:`SUPERSAMPLING`): 'draft' rasterises antialiased polygons at the output
size, where the shared edges of the translucent bell's triangles show as a faint lighter mesh;
'final' rasterises at three times the size in each direction and averages 3 x 3 blocks.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from PIL import Image  # Pillow: a dependency of Matplotlib, which writes PNGs with it

from jellysim.errors import InputError
from jellysim.render.frame import (
    Camera,
    DrawnTentacles,
    Frame,
    Jellyfish,
    Look,
    tentacle_radii,
    vertex_normals,
)
from jellysim.render.materials import (
    STRIPE_TRANSMIT,
    bell_material,
    bell_transmit,
    srgb,
    stripe_color,
    stripe_weight,
    tentacle_face_color,
    thread_look,
)

SUPERSAMPLING = {"draft": 1, "final": 3}  # quality name -> rasterised pixels per output pixel
DPI = 72.0  # one point is one pixel; n / 72 * 72 == n exactly for every n up to 30,000 px
NEAR_FRACTION = 1e-2  # near clipping distance, fraction of |look_at - location|
BOTTOM_DARKENING = 0.4  # background at the bottom row, fraction of water_color
AMBIENT = 0.3  # bell brightness where the key light does not reach
TENTACLE_AMBIENT = 0.6
KEY_LIGHT_UP, KEY_LIGHT_BACK = 1.0, 0.6  # key light direction: world up and towards the camera
FOG_EXTENTS = 2.0  # fog length in scene extents
MIN_HALF_WIDTH = 0.5  # px of the output image: the thinnest tentacle or particle drawn
SEGMENT_OVERLAP = 1.0  # px of the output image by which consecutive tentacle segments overlap
FLUID_TINT = 0.5  # fluid colour: water colour moved this fraction towards white
FLUID_OPACITY = 0.6
HEXAGON = np.stack(
    [np.cos(np.arange(6) * np.pi / 3.0), np.sin(np.arange(6) * np.pi / 3.0)], axis=1
)  # (6, 2) unit hexagon


class View(NamedTuple):
    """A camera fixed to an image: the basis, origin and focal length ``f`` in pixels of an
    image ``width`` x ``height`` px."""

    location: np.ndarray  # (3,) m
    right: np.ndarray  # (3,) unit
    up: np.ndarray  # (3,) unit
    forward: np.ndarray  # (3,) unit
    focal: float  # px
    width: int  # px
    height: int  # px


class Primitives(NamedTuple):
    """Polygons ready to draw, one row each: ``corners`` (M, K, 2) px, ``rgba`` (M, 4) in [0, 1],
    ``distance`` (M,) m from the camera."""

    corners: np.ndarray
    rgba: np.ndarray
    distance: np.ndarray


def make_view(camera: Camera, width: int, height: int) -> View:
    """The camera's basis and its focal length ``f = (W/2) / tan(angle/2)`` px."""
    right, up, forward = camera.basis()
    focal = 0.5 * width / math.tan(math.radians(0.5 * camera.angle))
    location = np.asarray(camera.location, dtype=np.float64)
    return View(location, right, up, forward, focal, width, height)


def project(points: np.ndarray, view: View) -> tuple[np.ndarray, np.ndarray]:
    """Pixel positions (..., 2) (x right, y down, origin at the image's top-left corner) and
    depths ``z_c`` (...,) m along the camera's forward axis of ``points`` (..., 3) m. Points with
    ``z_c <= 0`` are behind the camera: their pixels are meaningless."""
    relative = np.asarray(points, dtype=np.float64) - view.location
    depth = relative @ view.forward
    safe = np.where(np.abs(depth) > 1e-300, depth, 1e-300)
    scale = view.focal / safe
    pixels = np.stack(
        [
            0.5 * view.width + (relative @ view.right) * scale,
            0.5 * view.height - (relative @ view.up) * scale,
        ],
        axis=-1,
    )
    return pixels, depth


def render_preview(
    frame: Frame, camera: Camera, size: tuple[int, int], path: Path, quality: str = "draft"
) -> Path:
    """Write a PNG of ``frame`` seen by ``camera`` to ``path``: exactly ``size`` = (width,
    height) pixels, RGB 8 bit. ``quality`` is 'draft' or 'final' (see the module docstring).
    The same input gives the same pixels."""
    if quality not in SUPERSAMPLING:
        raise InputError(f"preview quality {quality!r}: expected one of {sorted(SUPERSAMPLING)}")
    width, height = (int(n) for n in size)
    if width < 1 or height < 1:
        raise InputError(f"preview size {size!r}: expected two positive integers (pixels)")
    samples = SUPERSAMPLING[quality]
    view = make_view(camera, width * samples, height * samples)
    water = frame.jellyfish[0].look.water_color if frame.jellyfish else Look().water_color
    row_colors = background_rows(water, view.height)

    extent = scene_extent(frame, view)
    focus = float(np.linalg.norm(np.asarray(camera.look_at) - view.location))
    fog_front = focus - 0.5 * extent
    fog_length = FOG_EXTENTS * extent if extent > 0.0 else math.inf
    near = NEAR_FRACTION * focus

    parts = []
    for jellyfish in frame.jellyfish:
        parts.append(bell_primitives(jellyfish, view, near))
        parts.append(manubrium_primitives(jellyfish, view, near))
        parts.append(gonad_primitives(jellyfish, view, near, samples))
        for group in jellyfish.drawn():
            if group.look.form == "ribbon":
                parts.append(arm_primitives(jellyfish, group, view, near))
            else:
                look = thread_look(jellyfish.look, group.look)
                parts.append(tentacle_primitives(group.positions, look, view, near, samples))
    if frame.fluid is not None and len(frame.fluid):
        parts.append(fluid_primitives(frame.fluid, frame.fluid_radius, water, view, near, samples))
    drawn = fog(merge(parts), row_colors, fog_front, fog_length)
    drawn = drawn._replace(rgba=np.column_stack([srgb(drawn.rgba[:, :3]), drawn.rgba[:, 3]]))

    image = rasterise(drawn, srgb(row_colors), view)
    if samples > 1:
        image = image.reshape(height, samples, width, samples, 3).mean(axis=(1, 3))
    pixels = np.clip(np.rint(image * 255.0), 0, 255).astype(np.uint8)
    Image.fromarray(pixels).save(path, format="PNG")
    return path


def background_rows(water: tuple[float, float, float], rows: int) -> np.ndarray:
    """Background colour (rows, 3) of each image row: ``water`` at the top, ``BOTTOM_DARKENING``
    times it at the bottom."""
    t = (np.arange(rows) + 0.5) / rows
    return np.asarray(water, dtype=np.float64) * (1.0 - (1.0 - BOTTOM_DARKENING) * t)[:, None]


def scene_extent(frame: Frame, view: View) -> float:
    """Diagonal (m) of the bounding box of the frame's bells and tentacles in front of the
    camera; 0 if there are none."""
    clouds = []
    for jellyfish in frame.jellyfish:
        for group in jellyfish.drawn():
            clouds.append(np.asarray(group.positions, dtype=np.float64).reshape(-1, 3))
        if jellyfish.bell_vertices is not None:
            clouds.append(np.asarray(jellyfish.bell_vertices, dtype=np.float64).reshape(-1, 3))
    points = np.concatenate(clouds) if clouds else np.empty((0, 3))
    in_front = (points - view.location) @ view.forward > 0.0
    points = points[np.isfinite(points).all(axis=1) & in_front]
    if not len(points):
        return 0.0
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def key_light(view: View) -> np.ndarray:
    """Unit direction (3,) towards the key light: above the scene and on the camera's side."""
    light = KEY_LIGHT_UP * np.array([0.0, 0.0, 1.0]) - KEY_LIGHT_BACK * view.forward
    return light / np.linalg.norm(light)


def visible(corners: np.ndarray, depth: np.ndarray, view: View, near: float) -> np.ndarray:
    """(M,) bool: every corner (M, K) in front of the near plane and the polygon not wholly
    outside the image (corners (M, K, 2) px)."""
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    inside = (
        (hi[:, 0] >= 0.0) & (lo[:, 0] <= view.width) & (hi[:, 1] >= 0.0) & (lo[:, 1] <= view.height)
    )
    return (depth > near).all(axis=1) & inside & np.isfinite(corners).all(axis=(1, 2))


def bell_primitives(jellyfish: Jellyfish, view: View, near: float) -> Primitives:
    """The bell's triangles (corners padded to a quadrilateral by repeating the last one),
    Lambert-shaded with two-sided normals."""
    if jellyfish.bell_vertices is None or jellyfish.bell_faces is None:
        return empty_primitives()
    vertices = np.asarray(jellyfish.bell_vertices, dtype=np.float64)
    all_faces = np.asarray(jellyfish.bell_faces, dtype=np.int64)
    pixels, depth = project(vertices, view)
    corners, corner_depth = pixels[all_faces], depth[all_faces]
    keep = visible(corners, corner_depth, view, near)
    faces, corners = all_faces[keep], corners[keep]

    normal = vertex_normals(vertices, all_faces)[faces].sum(axis=1)
    centroid = vertices[faces].mean(axis=1)
    to_camera = view.location - centroid
    normal *= np.where(np.einsum("ij,ij->i", normal, to_camera) < 0.0, -1.0, 1.0)[:, None]
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    normal /= np.where(length > 0.0, length, 1.0)
    lambert = np.clip(normal @ key_light(view), 0.0, 1.0)
    brightness = AMBIENT + (1.0 - AMBIENT) * lambert
    cos_theta = np.einsum("ij,ij->i", normal, to_camera) / np.linalg.norm(to_camera, axis=1)
    axis_offset = centroid - vertices.mean(axis=0)
    azimuth = np.arctan2(axis_offset[:, 0], axis_offset[:, 1])
    color, alpha = bell_shading(jellyfish.look, cos_theta, azimuth)
    rgb = color * brightness[:, None]
    return Primitives(
        corners=np.concatenate([corners, corners[:, 2:]], axis=1),
        rgba=np.column_stack([rgb, alpha]),
        distance=np.linalg.norm(to_camera, axis=1),
    )


def bell_shading(
    look: Look, cos_theta: np.ndarray, azimuth: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Unlit colour (n, 3) linear RGB and opacity (n,) of bell faces seen at ``theta`` from
    their normal and lying at ``azimuth`` (rad) about the bell's vertical axis: the bell's
    material with the stripes of :func:`~jellysim.render.materials.stripe_weight` mixed in
    (``STRIPE_TRANSMIT`` times as clear) and the Fresnel-like rim of
    :func:`~jellysim.render.materials.bell_transmit` (as POV-Ray draws them)."""
    transmit, lighten = bell_transmit(look, cos_theta)
    stripe = stripe_weight(look, azimuth)[:, None]
    bell = np.asarray(bell_material(look).base_color, dtype=np.float64)
    color = (1.0 - stripe) * bell + stripe * np.asarray(stripe_color(look), dtype=np.float64)
    color = color + lighten[:, None] * (1.0 - color)
    clear = transmit * (1.0 - (1.0 - STRIPE_TRANSMIT) * stripe[:, 0])
    return color, 1.0 - clear


def tentacle_primitives(
    tentacles: np.ndarray, look: Look, view: View, near: float, samples: int
) -> Primitives:
    """One quadrilateral per segment of the tentacles (N, P, 3) m, drawn in ``look``'s tentacle
    colour, radius and taper; the ribbon's edges at each particle are offset along the normal
    of the on-screen tangent (central differences) by the projected radius."""
    points = np.asarray(tentacles, dtype=np.float64)
    if points.ndim != 3 or points.shape[0] == 0 or points.shape[1] < 2:
        return empty_primitives()
    pixels, depth = project(points, view)  # (N, P, 2), (N, P)
    radii = tentacle_radii(points.shape[1], look)  # (P,) m
    half_width = np.maximum(
        radii * view.focal / np.where(depth > near, depth, near), MIN_HALF_WIDTH * samples
    )
    tangent = np.gradient(pixels, axis=1)
    length = np.linalg.norm(tangent, axis=2, keepdims=True)
    tangent = np.where(length > 1e-9, tangent / np.where(length > 1e-9, length, 1.0), [1.0, 0.0])
    offset = np.stack([-tangent[..., 1], tangent[..., 0]], axis=-1) * half_width[..., None]
    left, right = pixels + offset, pixels - offset
    corners = np.stack([left[:, :-1], left[:, 1:], right[:, 1:], right[:, :-1]], axis=2)
    # Overlap the neighbours by SEGMENT_OVERLAP: antialiased edges that merely touch let the
    # background show through as a line across the tentacle at every joint.
    along = np.diff(pixels, axis=1)
    along_length = np.linalg.norm(along, axis=2, keepdims=True)
    along = along / np.where(along_length > 1e-9, along_length, np.inf)
    stretch = 0.5 * SEGMENT_OVERLAP * samples * along[:, :, None, :]
    corners = (corners + np.array([-1.0, 1.0, 1.0, -1.0])[:, None] * stretch).reshape(-1, 4, 2)
    corner_depth = np.stack([depth[:, :-1], depth[:, 1:]], axis=2).reshape(-1, 2)
    keep = visible(corners, corner_depth, view, near)

    segment = np.diff(points, axis=1).reshape(-1, 3)[keep]
    middle = (0.5 * (points[:, :-1] + points[:, 1:])).reshape(-1, 3)[keep]
    seg_length = np.linalg.norm(segment, axis=1)
    cosine = (segment @ key_light(view)) / np.where(seg_length > 0.0, seg_length, 1.0)
    sine = np.sqrt(np.clip(1.0 - cosine**2, 0.0, 1.0))
    brightness = TENTACLE_AMBIENT + (1.0 - TENTACLE_AMBIENT) * sine
    # A ribbon faces the camera: the tentacle's face-on colour (as POV-Ray's tubes show it).
    rgb = np.asarray(tentacle_face_color(look)) * brightness[:, None]
    count = len(rgb)
    return Primitives(
        corners=corners[keep],
        rgba=np.column_stack([rgb, np.ones(count)]),
        distance=np.linalg.norm(middle - view.location, axis=1),
    )


def arm_primitives(
    jellyfish: Jellyfish, group: DrawnTentacles, view: View, near: float
) -> Primitives:
    """A ribbon group's ruffled arms as triangles in the group's colour and the bell's tissue
    (the meshes POV-Ray draws, :func:`jellysim.render.povray.arm_meshes`)."""
    from jellysim.render.povray import arm_meshes, arm_tissue
    from jellysim.render.ribbons import ribbon_primitives

    meshes = arm_meshes(jellyfish, group)
    return ribbon_primitives(meshes, group.look.color, arm_tissue(jellyfish.look), view, near)


def gonad_primitives(jellyfish: Jellyfish, view: View, near: float, samples: int) -> Primitives:
    """The horseshoe gonads as the tentacles' camera-facing ribbons, of the gonads' radius
    (untapered) in ``look.gonad_color``, opaque; sorted among the bell's triangles, so the
    bell's near side veils them."""
    if jellyfish.gonads is None:
        return empty_primitives()
    look = replace(
        jellyfish.look,
        tentacle_color=jellyfish.look.gonad_color,
        tentacle_radius=jellyfish.gonads.radius,
        tentacle_taper=1.0,
        tentacle_transparency=0.0,
    )
    return tentacle_primitives(jellyfish.gonads.paths, look, view, near, samples)


MANUBRIUM_SIDES = 16  # sides of the manubrium's cone in the preview


def manubrium_primitives(jellyfish: Jellyfish, view: View, near: float) -> Primitives:
    """The manubrium as the side of a ``MANUBRIUM_SIDES``-sided cone in the bell's colour and
    tissue, shaded as a ribbon is."""
    stalk = jellyfish.manubrium
    if stalk is None:
        return empty_primitives()
    from jellysim.render.ribbons import RibbonMesh, ribbon_primitives

    angle = 2.0 * np.pi * np.arange(MANUBRIUM_SIDES) / MANUBRIUM_SIDES
    ring = np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=1)
    vertices = np.concatenate(
        [stalk.top + stalk.top_radius * ring, stalk.bottom + stalk.bottom_radius * ring]
    )
    i = np.arange(MANUBRIUM_SIDES)
    j = (i + 1) % MANUBRIUM_SIDES
    faces = np.concatenate(
        [
            np.stack([i, j, j + MANUBRIUM_SIDES], 1),
            np.stack([i, j + MANUBRIUM_SIDES, i + MANUBRIUM_SIDES], 1),
        ]
    )
    mesh = RibbonMesh(vertices, faces, np.concatenate([ring, ring]))
    return ribbon_primitives([mesh], jellyfish.look.bell_color, jellyfish.look, view, near)


def fluid_primitives(
    fluid: np.ndarray,
    radius: float,
    water: tuple[float, float, float],
    view: View,
    near: float,
    samples: int,
) -> Primitives:
    """A small translucent hexagon per fluid particle."""
    points = np.asarray(fluid, dtype=np.float64).reshape(-1, 3)
    pixels, depth = project(points, view)
    half_width = np.maximum(
        radius * view.focal / np.where(depth > near, depth, near), MIN_HALF_WIDTH * samples
    )
    corners = pixels[:, None, :] + half_width[:, None, None] * HEXAGON
    keep = visible(corners, depth[:, None], view, near)
    count = int(keep.sum())
    rgb = np.asarray(water) + FLUID_TINT * (1.0 - np.asarray(water))
    return Primitives(
        corners=corners[keep],
        rgba=np.tile(np.append(rgb, FLUID_OPACITY), (count, 1)),
        distance=np.linalg.norm(points[keep] - view.location, axis=1),
    )


def empty_primitives() -> Primitives:
    return Primitives(np.empty((0, 4, 2)), np.empty((0, 4)), np.empty(0))


def merge(parts: list[Primitives]) -> Primitives:
    """All parts in one set, far to near (a stable sort: ties keep their input order). Polygons
    with fewer corners are padded by repeating their last corner."""
    parts = [part for part in parts if len(part.distance)]
    if not parts:
        return empty_primitives()
    corner_count = max(part.corners.shape[1] for part in parts)
    corners = np.concatenate(
        [
            np.concatenate(
                [part.corners] + [part.corners[:, -1:]] * (corner_count - part.corners.shape[1]),
                axis=1,
            )
            for part in parts
        ]
    )
    rgba = np.concatenate([part.rgba for part in parts])
    distance = np.concatenate([part.distance for part in parts])
    order = np.argsort(-distance, kind="stable")
    return Primitives(corners[order], rgba[order], distance[order])


def fog(drawn: Primitives, row_colors: np.ndarray, front: float, length: float) -> Primitives:
    """Blend each polygon's colour towards the background of its centre's image row, keeping
    the fraction ``exp(-max(d - front, 0) / length)`` of its contrast."""
    if not len(drawn.distance):
        return drawn
    row = np.clip(drawn.corners[:, :, 1].mean(axis=1).astype(np.int64), 0, len(row_colors) - 1)
    keep = np.exp(-np.maximum(drawn.distance - front, 0.0) / length)[:, None]
    rgba = drawn.rgba.copy()
    rgba[:, :3] = row_colors[row] + (rgba[:, :3] - row_colors[row]) * keep
    return drawn._replace(rgba=rgba)


def rasterise(drawn: Primitives, row_colors: np.ndarray, view: View) -> np.ndarray:
    """Draw the background rows (H, 3) and then the polygons in their order with Agg; returns
    RGB (H, W, 3) in [0, 1], the colours as given (sRGB)."""
    figure = Figure(figsize=(view.width / DPI, view.height / DPI), dpi=DPI)
    canvas = FigureCanvasAgg(figure)
    axes = figure.add_axes((0.0, 0.0, 1.0, 1.0))
    axes.set_axis_off()
    axes.imshow(
        row_colors[:, None, :],
        extent=(0.0, view.width, view.height, 0.0),
        aspect="auto",
        interpolation="nearest",
        zorder=0,
    )
    if len(drawn.distance):
        # An (M, K, 2) array, not the annotated list of arrays: Matplotlib's fast path.
        collection = PolyCollection(
            drawn.corners,  # type: ignore[arg-type]
            closed=True,
            facecolors=drawn.rgba,
            edgecolors="none",
            antialiased=True,
            zorder=1,
        )
        axes.add_collection(collection, autolim=False)
    axes.set_xlim(0.0, view.width)
    axes.set_ylim(view.height, 0.0)
    canvas.draw()
    buffer = np.asarray(canvas.buffer_rgba())
    if buffer.shape[:2] != (view.height, view.width):
        raise RuntimeError(f"Agg drew {buffer.shape[1::-1]} px, not {view.width, view.height}")
    return buffer[:, :, :3].astype(np.float64) / 255.0
