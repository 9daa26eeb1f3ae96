"""``jellysim render``: frames of one or more results, then a video (docs/rendering.md).

A render is a list of :class:`Member` jellyfish (a result, an offset, a phase shift and a look),
a camera per frame (framing the whole animation, or following the swimmers' mean motion), and a
renderer (POV-Ray or the built-in preview). Frames are written as ``frames/frame_NNNNN.png``
under a temporary name and renamed when complete, so an interrupted render resumes where it
stopped; ``render.json`` records the settings, and frames rendered with other settings are
never mixed in.
"""

from __future__ import annotations

import colorsys
import json
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from jellysim import fields
from jellysim.errors import InputError
from jellysim.io.folders import output_folder
from jellysim.io.result import Result
from jellysim.progress import progress
from jellysim.render.frame import (
    Camera,
    DrawnTentacles,
    Frame,
    Gonads,
    Jellyfish,
    Look,
    Manubrium,
)
from jellysim.render.materials import GroupLook, group_look

SETTINGS_FILE = "render.json"
VIEW_DIRECTION = np.array([0.0, 1.0, -0.25])  # the camera looks along +y, a little down
FIELD_OF_VIEW = 40.0  # degrees, horizontal
SCHOOL_SPACING = 1.3  # neighbours in a school, in jellyfish sizes


@dataclass(frozen=True)
class MemberGroup:
    """One tentacle group of a :class:`Member`: its drawn tentacles ``positions`` (F, D, P, 3) m
    (the group's own particles: no padding), its resolved ``look``, and ``first`` the drawn
    index of its first row."""

    positions: np.ndarray
    look: GroupLook
    first: int


@dataclass(frozen=True)
class Member:
    """One jellyfish of the picture: a result, shifted by ``offset`` (3,) m, ``phase`` frames
    later in its cycle (looping), drawn with ``look`` and its tentacle ``groups``."""

    result: Result
    offset: np.ndarray
    phase: int
    look: Look
    groups: tuple[MemberGroup, ...]
    bell_vertices: Any  # h5py dataset (F, V, 3) or None
    bell_faces: np.ndarray | None
    fluid: Any = None  # h5py dataset (F, K, D) of fluid particles, D = 2 or 3, or None
    fluid_alive: Any = None  # h5py dataset (F, K) bool, or None
    shift: np.ndarray | None = None  # (F, 3) m added per frame: undoes the phase's swim travel

    def _move(self, index: int) -> np.ndarray:
        return self.offset if self.shift is None else self.offset + self.shift[index]

    def fluid_points(self, index: int) -> np.ndarray | None:
        """Fluid particles alive at the frame, (K', 3) m; a 2-D fluid (x, y up) drawn in the
        x-z plane."""
        if self.fluid is None:
            return None
        k = (index + self.phase) % self.fluid.shape[0]
        points = np.asarray(self.fluid[k], dtype=np.float64)
        if self.fluid_alive is not None:
            points = points[np.asarray(self.fluid_alive[k], dtype=bool)]
        return to_world(points) + self._move(index)

    def frame(self, index: int) -> Jellyfish:
        count = self.result.frames
        k = (index + self.phase) % count
        move = self._move(index)
        vertices = None
        if self.bell_vertices is not None:
            vertices = np.asarray(self.bell_vertices[k], dtype=np.float64) + move
        groups = tuple(
            DrawnTentacles(finite_rows(g.positions[k]) + move, g.look, g.first) for g in self.groups
        )
        centre = None
        if self.result.has(fields.BELL_MARGIN):
            centre = self.result.read(fields.BELL_MARGIN, k).astype(np.float64).mean(axis=0) + move
        return Jellyfish(
            np.empty((0, 2, 3)),
            vertices,
            self.bell_faces,
            self.look,
            groups=groups,
            centre=centre,
            manubrium=manubrium(vertices, centre, groups),
            gonads=gonads(vertices, self.bell_faces, centre, self.look.gonads),
        )

    def centres(self) -> np.ndarray:
        """The bell's margin centre per frame (F, 3), shifted and phased as drawn (the centre
        of the drawn box for a result without a bell)."""
        if not self.result.has(fields.BELL_MARGIN):
            return self.boxes().mean(axis=1)
        margin_centre = self.result.margin.mean(axis=1)
        k = (np.arange(margin_centre.shape[0]) + self.phase) % margin_centre.shape[0]
        shift = 0.0 if self.shift is None else self.shift
        return margin_centre[k] + self.offset + shift

    def boxes(self) -> np.ndarray:
        """Bounding box (F, 2, 3) of what is drawn, per frame."""
        frames = self.result.frames
        low = np.full((frames, 3), np.inf)
        high = np.full((frames, 3), -np.inf)
        for group in self.groups:
            points = group.positions.reshape(frames, -1, 3)
            if points.shape[1] > 0:
                low = np.fmin(low, np.nanmin(points, axis=1))  # padding and gaps are not drawn
                high = np.fmax(high, np.nanmax(points, axis=1))
        if self.fluid is not None:
            for frame in range(frames):
                points = to_world(np.asarray(self.fluid[frame], dtype=np.float64))
                low[frame] = np.minimum(low[frame], points.min(axis=0))
                high[frame] = np.maximum(high[frame], points.max(axis=0))
        if self.bell_vertices is not None:
            vertices = np.asarray(self.bell_vertices[:], dtype=np.float64)
            low = np.minimum(low, vertices.min(axis=1))
            high = np.maximum(high, vertices.max(axis=1))
        k = (np.arange(low.shape[0]) + self.phase) % low.shape[0]
        shift = 0.0 if self.shift is None else self.shift[:, None]
        return np.stack([low[k], high[k]], axis=1) + self.offset + shift


def finite_rows(tentacles: np.ndarray) -> np.ndarray:
    """Drawn tentacles (N, P, 3) up to the first particle not finite in every one of them (a
    padded or diverged chain's tail): nothing NaN reaches a renderer."""
    finite = np.isfinite(tentacles).all(axis=(0, 2))
    return tentacles if finite.all() else tentacles[:, : int(np.argmin(finite))]


MANUBRIUM_FLARE = 1.3  # the manubrium's radius under the bell, in radii of the arms' circle
AXIS_FRACTION = 0.15  # the subumbrella's centre: the lowest bell vertex this near the axis


def manubrium(
    vertices: np.ndarray | None, centre: np.ndarray | None, groups: Sequence[DrawnTentacles]
) -> Manubrium | None:
    """The stalk oral arms hang from, for a frame with a bell and a group placed at the mouth:
    from the subumbrella's centre (on the vertical axis through the margin ``centre``, at the
    height of the lowest bell vertex within ``AXIS_FRACTION`` of the bell's radius of that axis
    and above the roots: the inner apex)
    down to the centre of the mouth groups' roots, ``MANUBRIUM_FLARE`` times their circle's
    radius at the top, their circle's at the bottom. None otherwise."""
    roots = [g.positions[:, 0] for g in groups if g.look.placement == "mouth" and g.positions.size]
    if vertices is None or centre is None or not roots:
        return None
    points = np.concatenate(roots)
    bottom = points.mean(axis=0)
    radius = float(np.linalg.norm((points - bottom)[:, :2], axis=1).mean())
    horizontal = np.linalg.norm((vertices - centre)[:, :2], axis=1)
    near_axis = (horizontal <= AXIS_FRACTION * horizontal.max()) & (vertices[:, 2] > bottom[2])
    if not near_axis.any():
        return None
    top = np.array([centre[0], centre[1], vertices[near_axis, 2].min()])  # on the axis
    return Manubrium(top, bottom, MANUBRIUM_FLARE * radius, radius)


GONAD_CENTRE = 0.42  # a horseshoe's centre from the bell's axis, in bell radii
GONAD_LOOP = 0.17  # a horseshoe's radius, in bell radii (less where many would touch)
GONAD_OPENING = 0.3  # the horseshoe's gap towards the margin, in turns of its loop
GONAD_THICKNESS = 0.05  # the tube's radius, in bell radii
GONAD_POINTS = 25  # points along each horseshoe


def gonads(
    vertices: np.ndarray | None, faces: np.ndarray | None, centre: np.ndarray | None, count: int
) -> Gonads | None:
    """``count`` horseshoe gonads on the subumbrella of the bell surface ``vertices`` (V, 3) m,
    ``faces`` (M, 3), about the vertical axis through ``centre`` (3,) m (the surface's mean when
    None), placed afresh each frame so that they follow the bell as it pulses.

    With ``R`` the surface's largest distance from the axis in this frame, horseshoe ``k`` is an
    arc of radius ``GONAD_LOOP R`` about a point ``GONAD_CENTRE R`` from the axis at the
    interradial angle ``2 pi (k + 1/2) / count`` (between the oral arms' default angles), open
    towards the margin (a gap of ``GONAD_OPENING`` of a turn), its points lifted to the lowest
    crossing of the vertical through them with the surface (the subumbrella), less the tube's
    radius ``GONAD_THICKNESS R``: just under the subumbrella, touching it. None when
    ``count`` is 0, there is no surface, or no point lies under it."""
    if count <= 0 or vertices is None or faces is None or not len(faces):
        return None
    axis = vertices.mean(axis=0) if centre is None else centre
    radius = float(np.linalg.norm((vertices - axis)[:, :2], axis=1).max())
    loop = radius * min(GONAD_LOOP, 0.8 * GONAD_CENTRE * math.sin(math.pi / count))
    half_gap = math.pi * GONAD_OPENING
    turn = np.linspace(half_gap, 2.0 * math.pi - half_gap, GONAD_POINTS)  # 0 points outwards
    paths = []
    for k in range(count):
        azimuth = 2.0 * math.pi * (k + 0.5) / count
        outward = np.array([math.cos(azimuth), math.sin(azimuth)])
        across = np.array([-outward[1], outward[0]])
        middle = axis[:2] + GONAD_CENTRE * radius * outward
        xy = middle + loop * (np.cos(turn)[:, None] * outward + np.sin(turn)[:, None] * across)
        paths.append(np.column_stack([xy, lowest_crossing(vertices, faces, xy)]))
    points = np.stack(paths)
    if not np.isfinite(points).all():
        return None
    thickness = GONAD_THICKNESS * radius
    points[..., 2] -= thickness  # the tube's top touches the subumbrella from below
    return Gonads(points, thickness)


def lowest_crossing(vertices: np.ndarray, faces: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Height (N,) m of the lowest crossing of the vertical line through each point ``xy``
    (N, 2) m with the triangles ``faces`` of ``vertices`` (barycentric in the horizontal plane;
    upright triangles skipped); points without a crossing take the height of the nearest point
    along ``xy`` with one (NaN when none has one)."""
    corners = vertices[faces]  # (M, 3, 3)
    a, b, c = corners[:, 0, :2], corners[:, 1, :2], corners[:, 2, :2]
    e1, e2 = b - a, c - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]  # (M,)
    flat = np.abs(det) > 1e-12 * max(float(np.abs(det).max()), 1e-300)
    e1, e2, a, det = e1[flat], e2[flat], a[flat], det[flat]
    z = corners[flat, :, 2]
    d = xy[:, None, :] - a[None, :, :]  # (N, M, 2)
    u = (d[..., 0] * e2[:, 1] - d[..., 1] * e2[:, 0]) / det
    v = (e1[:, 0] * d[..., 1] - e1[:, 1] * d[..., 0]) / det
    inside = (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0)
    height = z[:, 0] + u * (z[:, 1] - z[:, 0]) + v * (z[:, 2] - z[:, 0])
    lowest = np.where(inside, height, np.inf).min(axis=1)
    hit = np.isfinite(lowest)
    if not hit.any():
        return np.full(len(xy), np.nan)
    index = np.arange(len(xy))
    return np.interp(index, index[hit], lowest[hit])


def to_world(points: np.ndarray) -> np.ndarray:
    """Particle positions (K, D) as 3-D world points: a 2-D fluid's (x, y up) becomes (x, 0, y)."""
    if points.shape[-1] == 3:
        return points
    world = np.zeros((*points.shape[:-1], 3))
    world[..., 0], world[..., 2] = points[..., 0], points[..., 1]
    return world


def fluid_radius(result: Result) -> float:
    """Drawn radius (m) of a fluid particle: half the particle spacing (the result's
    ``particle_spacing`` attribute, else the median nearest-neighbour distance at frame 0)."""
    spacing = result.file.attrs.get("particle_spacing")
    if spacing is None:
        from scipy.spatial import cKDTree

        points = to_world(result.read(fields.FLUID_POSITION, 0).astype(np.float64))
        distances, _ = cKDTree(points).query(points, k=2)
        spacing = float(np.median(distances[:, 1]))
    return 0.5 * float(spacing)


def scene_look(scene: Any, overrides: Sequence[str] = ()) -> Look:
    """The look of a result's scene ([look] table, with ``look.KEY=VALUE`` overrides), the
    drawn tentacle radius resolved."""
    if overrides:
        from jellysim.config import load_scene
        from jellysim.config.load import parse_override

        for item in overrides:
            key = parse_override(item)[0]
            if not key.startswith("look."):
                raise InputError(
                    f"--set {item}: render changes only [look] keys (look.*); "
                    f"'{key}' needs a new simulation (jellysim run --set)"
                )
        scene = load_scene(scene, list(overrides))
    look = scene.look
    radius = look.tentacle_radius or 0.25 * scene.tentacles.spacing
    stripes = scene.bell.lobes // 2 if look.stripes is None else look.stripes
    # Keys a scene leaves unset (so that its stored text stays as before they existed) take the
    # renderer's defaults.
    default = Look()

    def unset(value: Any, fallback: Any) -> Any:
        return fallback if value is None else value

    return Look(
        bell_color=look.bell_color,
        tentacle_color=look.tentacle_color,
        bell_transparency=look.bell_transparency,
        glow=look.glow,
        water_color=look.water_color,
        tentacle_radius=radius,
        tentacle_taper=look.tentacle_taper,
        tentacle_transparency=unset(look.tentacle_transparency, default.tentacle_transparency),
        rim=unset(look.rim, default.rim),
        stripes=stripes,
        marine_snow=unset(look.marine_snow, default.marine_snow),
        light_shafts=unset(look.light_shafts, default.light_shafts),
        depth_of_field=unset(look.depth_of_field, default.depth_of_field),
        gonads=unset(look.gonads, default.gonads),
        gonad_color=unset(look.gonad_color, default.gonad_color),
    )


SCHOOL_HUE = 0.04  # a school member's hue turns at most this much of the colour wheel (±14°) ...
SCHOOL_LIGHTNESS = 0.15  # ... and its lightness by at most this fraction: one species, many shades
SCHOOL_FOLLOW = 0.25  # a school is followed once it travels this much of one jellyfish's size
SCHOOL_DROP = 0.45  # each row of a school hangs this much of the spacing lower than the one before


def _shift_hue(
    color: tuple[float, float, float], turn: float, lighten: float = 0.0
) -> tuple[float, float, float]:
    """``color`` with its hue turned by ``turn`` of the wheel and its lightness scaled by
    ``1 + lighten`` (kept within [0, 1])."""
    h, lightness, s = colorsys.rgb_to_hls(*color)
    lightness = min(1.0, max(0.0, lightness * (1.0 + lighten)))
    r, g, b = colorsys.hls_to_rgb((h + turn) % 1.0, lightness, s)
    return (r, g, b)


FLUID_MODES = ("auto", "spheres", "surface", "none")


def make_members(
    results: Sequence[Result],
    school: int,
    interpolation: int | None,
    seed: int,
    look_overrides: Sequence[str] = (),
    fluid: bool = True,
) -> list[Member]:
    """The jellyfish to draw: every result once, or a school of ``school`` jellyfish cycling
    through the results on a jittered grid (each row further back and lower), with random phase
    shifts and small shifts of hue and lightness; their fluid particles too when ``fluid``."""
    drawn = [member_groups(r, interpolation, scene_look(r.scene, look_overrides)) for r in results]
    count = max(school, len(results))
    rng = np.random.default_rng(seed)
    size = max(_extent(r, d, fluid) for r, d in zip(results, drawn, strict=True))
    columns = math.ceil(math.sqrt(count))
    members = []
    for index in range(count):
        which = index % len(results)
        result = results[which]
        look = scene_look(result.scene, look_overrides)
        groups = drawn[which]
        offset = np.zeros(3)
        phase = 0
        if count > 1:
            row, column = divmod(index, columns)
            jitter = rng.uniform(-0.25, 0.25, size=3)
            offset = (
                SCHOOL_SPACING
                * size
                * np.array(
                    [
                        column - (columns - 1) / 2 + jitter[0],
                        row + jitter[1],
                        -SCHOOL_DROP * row + 0.4 * jitter[2],
                    ]
                )
            )
            phase = int(rng.integers(0, result.frames))
            if index >= len(results):
                golden = 0.618034 * index % 1.0  # evenly spread over the members
                turn = SCHOOL_HUE * (2.0 * golden - 1.0)
                lighten = SCHOOL_LIGHTNESS * (2.0 * (0.618034 * golden * 7.0 % 1.0) - 1.0)
                look = replace(
                    look,
                    bell_color=_shift_hue(look.bell_color, turn, lighten),
                    tentacle_color=_shift_hue(look.tentacle_color, turn, lighten),
                )
                groups = tuple(
                    replace(g, look=replace(g.look, color=_shift_hue(g.look.color, turn, lighten)))
                    for g in groups
                )
        has_bell = result.has(fields.BELL_SURFACE_VERTICES)
        has_fluid = fluid and result.has(fields.FLUID_POSITION)
        shift = _phase_shift(result, phase) if phase else None
        members.append(
            Member(
                result=result,
                offset=offset,
                phase=phase,
                look=look,
                groups=groups,
                bell_vertices=result.dataset(fields.BELL_SURFACE_VERTICES) if has_bell else None,
                bell_faces=result.bell_surface_faces if has_bell else None,
                fluid=result.dataset(fields.FLUID_POSITION) if has_fluid else None,
                fluid_alive=(
                    result.dataset(fields.FLUID_ALIVE) if result.has(fields.FLUID_ALIVE) else None
                ),
                shift=shift,
            )
        )
    return members


def member_groups(result: Result, interpolation: int | None, look: Look) -> tuple[MemberGroup, ...]:
    """A result's drawn tentacles group by group
    (:func:`~jellysim.interpolation.interpolate_groups`), each with its look resolved from its
    keys over ``look`` (:func:`~jellysim.render.materials.group_look`); none without
    tentacles."""
    from jellysim.interpolation import interpolate_groups

    if not result.has(fields.TENTACLE_POSITION):
        return ()
    groups = []
    first = 0
    for drawn in interpolate_groups(result, interpolation):
        groups.append(
            MemberGroup(drawn.positions, group_look(look, drawn.tentacles, drawn.name), first)
        )
        first += drawn.positions.shape[1]
    return tuple(groups)


def _phase_shift(result: Result, phase: int) -> np.ndarray | None:
    """(F, 3) m: what brings a swimmer shown ``phase`` frames later back onto the straight line
    of its mean swim at each frame, so that a phase shift shifts the pulse, not the place."""
    if not result.has(fields.BELL_MARGIN):
        return None
    centres = result.margin.mean(axis=1)
    frames = centres.shape[0]
    t = np.arange(frames, dtype=np.float64)
    if frames < 2:
        return None
    slope, intercept = np.polyfit(t, centres, 1)
    trend = intercept + t[:, None] * slope
    return trend - trend[(np.arange(frames) + phase) % frames]


def _extent(result: Result, groups: Sequence[MemberGroup], fluid: bool = True) -> float:
    """The largest extent (m) of one jellyfish (and its fluid, when drawn) in any one frame: its
    size, not how far it swims."""
    frames = result.frames
    parts = [g.positions.reshape(frames, -1, 3) for g in groups]
    if fluid and result.has(fields.FLUID_POSITION):
        parts.append(to_world(result.fluid_positions.astype(np.float64)))
    if result.has(fields.BELL_SURFACE_VERTICES):
        parts.append(result.bell_surface_vertices.astype(np.float64))
    points = np.concatenate(parts, axis=1) if parts else np.empty((frames, 0, 3))
    if points.shape[1] == 0:
        return 1.0
    return float(np.nanmax(np.nanmax(points, axis=1) - np.nanmin(points, axis=1)))


def camera_targets(
    members: Sequence[Member], frames: int, mode: str
) -> tuple[np.ndarray, np.ndarray, str]:
    """Where the camera looks at each frame, (F, 3) m, the half-size (3,) m of the box about
    those points that holds everything drawn, and the mode used.

    ``fixed`` frames the union of every frame's bounding box; ``follow`` moves with the
    least-squares straight line through the jellyfish's centres (so the pulses of a swimmer's
    speed stay visible) and frames the largest box about it; ``auto`` follows when the centres
    travel further than the jellyfish's size, or, for several jellyfish (a school, which fills
    the picture), further than a quarter of the largest one's: so that the school stays in the
    middle of the picture rather than drifting across a fixed one. Either way the targets lie
    on a straight line, at constant speed.
    """
    boxes = np.stack([m.boxes()[:frames] for m in members])  # (J, F, 2, 3)
    low, high = boxes[:, :, 0].min(axis=0), boxes[:, :, 1].max(axis=0)  # (F, 3)
    centres = np.mean([m.centres()[:frames] for m in members], axis=0)  # (F, 3)
    one = float((boxes[:, :, 1] - boxes[:, :, 0]).max())  # the largest jellyfish in any frame
    travel = float(np.linalg.norm(centres[-1] - centres[0]))
    if mode == "auto":
        reach = one if len(members) == 1 else SCHOOL_FOLLOW * one
        mode = "follow" if travel > reach else "fixed"
    if mode == "follow":
        t = np.arange(frames, dtype=np.float64)
        slope, intercept = np.polyfit(t, centres, 1) if frames > 1 else (np.zeros(3), centres[0])
        trend = intercept + t[:, None] * slope
        rel_low, rel_high = (low - trend).min(axis=0), (high - trend).max(axis=0)
        targets = trend + 0.5 * (rel_low + rel_high)
        half = 0.5 * (rel_high - rel_low)
    else:
        overall_low, overall_high = low.min(axis=0), high.max(axis=0)
        targets = np.broadcast_to(0.5 * (overall_low + overall_high), (frames, 3))
        half = 0.5 * (overall_high - overall_low)
    return targets, half, mode


def frame_cameras(
    members: Sequence[Member], frames: int, size: tuple[int, int], mode: str
) -> tuple[list[Camera], float, str]:
    """A camera per frame, the framed extent (m) and the mode used (:func:`camera_targets`):
    looking along :data:`VIEW_DIRECTION` from the nearest distance at which the framed box fits
    the picture of ``size`` (width, height) pixels."""
    targets, half, mode = camera_targets(members, frames, mode)
    width, height = size
    direction = VIEW_DIRECTION / np.linalg.norm(VIEW_DIRECTION)
    probe = Camera(location=-direction, look_at=np.zeros(3), angle=FIELD_OF_VIEW)
    right, up, forward = probe.basis()
    tan_h = math.tan(math.radians(FIELD_OF_VIEW) / 2.0)
    tan_v = tan_h * height / width
    # The nearest distance at which every corner of the box projects inside the picture.
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    offsets = corners * half
    needed = np.maximum(
        np.abs(offsets @ right) / tan_h - offsets @ forward,
        np.abs(offsets @ up) / tan_v - offsets @ forward,
    )
    distance = 1.08 * float(needed.max())
    cameras = [
        Camera(location=target - distance * forward, look_at=np.array(target), angle=FIELD_OF_VIEW)
        for target in targets
    ]
    radius = float(np.linalg.norm(half))
    return cameras, 2.0 * radius, mode


def outside(camera: Camera, box: tuple[np.ndarray, np.ndarray]) -> Camera:
    """The camera moved back along its view, if need be, to stand in front of the box (the
    tank): a tenth of the box's depth before its front face."""
    _, _, forward = camera.basis()
    front = box[0][1] - 0.1 * (box[1][1] - box[0][1])
    if camera.location[1] <= front or forward[1] <= 0.0:
        return camera
    back = (camera.location[1] - front) / forward[1]
    return replace(camera, location=camera.location - back * forward)


@dataclass(frozen=True)
class RenderSettings:
    """What decides how a frame looks; frames rendered with other settings are not reused."""

    renderer: str
    quality: str
    size: tuple[int, int]
    camera: str
    room: bool
    school: int
    interpolation: int | None
    fluid: str
    seed: int
    looks: tuple[str, ...]
    results: tuple[str, ...]
    scenes: tuple[str, ...]

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=1, sort_keys=True)


def _check_settings(folder: Path, settings: RenderSettings, force: bool) -> None:
    path = folder / SETTINGS_FILE
    frames = folder / "frames"
    if force or not path.is_file() or not any(frames.glob("frame_*.png")):
        for stale in frames.glob("frame_*.png"):
            stale.unlink()
        return
    if path.read_text(encoding="utf-8") != settings.to_json():
        raise InputError(
            f"{folder}: its frames were rendered with other settings ({SETTINGS_FILE}); "
            "--force renders them again"
        )


def render(
    results: Sequence[Result],
    out: Path,
    *,
    renderer: str = "auto",
    quality: str = "draft",
    size: tuple[int, int] = (640, 480),
    camera: str = "auto",
    room: bool = False,
    school: int = 1,
    interpolation: int | None = None,
    fluid: str = "auto",
    seed: int = 0,
    gif: bool = False,
    video: bool = True,
    jobs: int | None = None,
    frames: tuple[int, int] | None = None,
    look_overrides: Sequence[str] = (),
    force: bool = False,
    quiet: bool = True,
    notice: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Render ``results`` into ``out``: ``frames/``, ``pov/`` (POV-Ray scenes), ``movie.mp4``
    and optionally ``movie.gif``. Returns paths and timings.

    ``fluid``: "spheres", "surface" (one blobby surface), "none", or "auto": the fluid particles
    as spheres for fluid-only results, not drawn when there is a jellyfish (its water would hide
    it; the scene's water colour and fog stand for the water)."""
    from jellysim.render import povray

    say = notice or (lambda text: print(text, file=sys.stderr))
    povray_path = povray.find_povray()
    if renderer == "povray" and povray_path is None:
        raise InputError(
            "--renderer povray: POV-Ray is not installed (Debian/Ubuntu: "
            "sudo apt-get install povray); --renderer preview needs no system package"
        )
    if renderer == "auto":
        renderer = "povray" if povray_path else "preview"
        if povray_path is None:
            say(
                "notice: POV-Ray not found (sudo apt-get install povray); "
                "using the built-in preview renderer"
            )
    if fluid not in FLUID_MODES:
        raise InputError(f"--fluid {fluid}: expected one of {', '.join(FLUID_MODES)}")
    if fluid == "auto":
        jellyfish = any(
            r.has(fields.TENTACLE_POSITION) or r.has(fields.BELL_SURFACE_VERTICES) for r in results
        )
        fluid = "none" if jellyfish else "spheres"
    if quality not in povray.QUALITIES:
        raise InputError(f"--quality {quality}: expected one of draft, final")
    for result in results:
        scene_look(result.scene, look_overrides)  # bad --set fails before anything is written
    frame_count = min(r.frames for r in results)
    first, stop = (0, frame_count) if frames is None else frames
    if not 0 <= first < stop <= frame_count:
        raise InputError(f"--frames {first}:{stop}: the result has frames 0:{frame_count}")
    frames_dir = output_folder(out / "frames")
    fps = float(results[0].file.attrs["fps"])
    settings = RenderSettings(
        renderer=renderer,
        quality=quality,
        size=size,
        camera=camera,
        room=room,
        school=school,
        interpolation=interpolation,
        fluid=fluid,
        seed=seed,
        looks=tuple(look_overrides),
        results=tuple(str(r.path.resolve()) for r in results),
        scenes=tuple(r.scene_text for r in results),
    )
    _check_settings(out, settings, force)
    (out / SETTINGS_FILE).write_text(settings.to_json(), encoding="utf-8")

    members = make_members(
        results, school, interpolation, seed, look_overrides, fluid=fluid != "none"
    )
    cameras, extent, camera_mode = frame_cameras(members, frame_count, size, camera)
    room_box = None
    if room:
        boxes = np.concatenate([m.boxes()[:frame_count] for m in members])
        room_box = povray.room_box(boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0))
        cameras = [outside(c, room_box) for c in cameras]
    wanted = range(first, stop)
    todo = [i for i in wanted if not (frames_dir / f"frame_{i:05d}.png").is_file()]
    pov_dir = out / "pov"
    if renderer == "povray":
        pov_dir.mkdir(exist_ok=True)
    level = povray.QUALITIES[quality]
    cores = os.cpu_count() or 1
    jobs = max(1, min(jobs or cores, max(1, len(todo))))

    fluids = [m for m in members if m.fluid is not None]
    particle_radius = fluid_radius(fluids[0].result) if fluids else 0.0

    def frame_at(index: int) -> Frame:
        points = [p for m in fluids if (p := m.fluid_points(index)) is not None]
        return Frame(
            time=float(index) / fps,
            jellyfish=[m.frame(index) for m in members],
            fluid=np.concatenate(points) if points else None,
            fluid_radius=particle_radius,
        )

    def one(index: int) -> None:
        image = frames_dir / f"frame_{index:05d}.png"
        if renderer == "povray":
            assert povray_path is not None
            scene_file = pov_dir / f"frame_{index:05d}.pov"
            text = povray.scene_text(
                frame_at(index), cameras[index], size, level, extent, room_box, fluid, seed=seed
            )
            scene_file.write_text(text, encoding="utf-8")
            povray.render_file(povray_path, scene_file, image, size, level, max(1, cores // jobs))
        else:
            from jellysim.render.preview import render_preview

            partial = image.with_name(image.stem + ".part.png")
            render_preview(frame_at(index), cameras[index], size, partial, quality)
            partial.replace(image)

    start = time.perf_counter()
    with (
        progress(len(wanted), len(wanted) - len(todo), quiet, "rendering") as bar,
        ThreadPoolExecutor(max_workers=jobs) as pool,
    ):
        for _ in pool.map(one, todo):
            bar.update(1)
    wall = time.perf_counter() - start
    outputs: dict[str, Any] = {
        "frames": frames_dir,
        "rendered": len(todo),
        "kept": len(wanted) - len(todo),
        "renderer": renderer,
        "camera": camera_mode,
        "seconds_per_frame": wall / len(todo) if todo else 0.0,
    }
    if video:
        from jellysim.render.video import encode_gif, encode_mp4

        files = [frames_dir / f"frame_{i:05d}.png" for i in wanted]
        outputs["mp4"] = encode_mp4(files, fps, out / "movie.mp4")
        if gif:
            outputs["gif"] = encode_gif(files, out / "movie.gif", fps)
    return outputs
