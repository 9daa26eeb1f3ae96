"""What a renderer draws: one frame's geometry, the camera and the look, in world coordinates
(SI units, z up, DESIGN §3). Renderers (POV-Ray, the built-in preview) take these and nothing
else, so they cannot drift apart in what they show.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from jellysim.render.materials import GroupLook

RGB = tuple[float, float, float]
FLUID_COLOR: RGB = (0.6, 0.8, 1.0)  # fluid particles, linear RGB (every renderer and export)


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: ``location`` and ``look_at`` (3,) m, ``up`` the world's up (+z), and
    ``angle`` the horizontal field of view in degrees."""

    location: np.ndarray
    look_at: np.ndarray
    angle: float = 40.0
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit vectors (right, true up, forward) of the image plane."""
        forward = self.look_at - self.location
        forward = forward / np.linalg.norm(forward)
        right = np.cross(forward, self.up)
        right = right / np.linalg.norm(right)
        return right, np.cross(right, forward), forward


@dataclass(frozen=True)
class Look:
    """Colours (linear RGB in [0, 1]) and materials of one jellyfish and its water."""

    bell_color: RGB = (0.85, 0.55, 0.35)
    tentacle_color: RGB = (0.80, 0.45, 0.30)
    bell_transparency: float = 0.5  # 0 opaque, 1 invisible
    glow: float = 0.3  # emission of the bell at final quality, 0 to 1
    water_color: RGB = (0.05, 0.20, 0.35)
    tentacle_radius: float = 0.004  # m at the root
    tentacle_taper: float = 0.3  # tip radius / root radius
    tentacle_transparency: float = 0.3  # deep water mixed into a tentacle face-on (faked)
    rim: float = 0.6  # Fresnel-like rim: 0 the same at every angle, 1 opaque at the silhouette
    stripes: int = 0  # radial stripes seen through the bell, 0 none
    marine_snow: int = 400  # drifting particles in the water around the camera
    light_shafts: float = 0.5  # brightness of the light shafts from above at final quality
    depth_of_field: float = 1.0  # focal blur at final quality, 0 everything sharp
    gonads: int = 0  # horseshoe gonads seen through the bell, 0 none
    gonad_color: RGB = (0.45, 0.25, 0.85)  # a violet


@dataclass(frozen=True)
class DrawnTentacles:
    """One group of a jellyfish's drawn tentacles in one frame: ``positions`` (N, P, 3) m, root
    first, every point finite (a padded result's NaN rows trimmed); ``look`` its resolved look
    (:func:`jellysim.render.materials.group_look`); ``first`` the drawn index of its first row
    among the jellyfish's drawn tentacles (seeds per-arm differences, such as a ribbon's
    phase)."""

    positions: np.ndarray
    look: GroupLook
    first: int = 0


@dataclass(frozen=True)
class Manubrium:
    """The stalk oral arms hang from: a cone from ``top`` (3,) m (the subumbrella's centre), of
    radius ``top_radius`` m, down to ``bottom`` (3,) m (the centre of the arms' roots) of radius
    ``bottom_radius`` m (their circle's)."""

    top: np.ndarray
    bottom: np.ndarray
    top_radius: float
    bottom_radius: float


@dataclass(frozen=True)
class Gonads:
    """A jellyfish's horseshoe gonads in one frame: ``paths`` (G, S, 3) m, the centre line of
    each horseshoe from one open end round to the other, drawn as a tube of ``radius`` m."""

    paths: np.ndarray
    radius: float


@dataclass(frozen=True)
class Jellyfish:
    """One jellyfish in one frame.

    ``bell_vertices`` (V, 3) m and ``bell_faces`` (M, 3) int (counter-clockwise seen from
    outside), or both None for a result without a bell body; ``tentacles`` (N, P, 3) m, root
    first, drawn as threads in ``look``'s tentacle colour, radius and taper; ``groups`` further
    drawn tentacles, each group in its own look (the render pipeline puts every scene group
    here and leaves ``tentacles`` empty); ``centre`` (3,) m the bell's margin centre (the axis
    ribbons turn out from), ``manubrium`` the stalk of a scene with oral arms, ``gonads`` the
    horseshoes seen through the bell when ``look.gonads`` asks for them.
    """

    tentacles: np.ndarray
    bell_vertices: np.ndarray | None
    bell_faces: np.ndarray | None
    look: Look
    groups: tuple[DrawnTentacles, ...] = ()
    centre: np.ndarray | None = None
    manubrium: Manubrium | None = None
    gonads: Gonads | None = None

    def drawn(self) -> tuple[DrawnTentacles, ...]:
        """Every group to draw: ``tentacles`` in the jellyfish's own look (if any), then
        ``groups``."""
        from jellysim.render.materials import group_look

        own = np.asarray(self.tentacles)
        if own.ndim != 3 or own.shape[0] == 0:
            return self.groups
        return (DrawnTentacles(own, group_look(self.look)), *self.groups)


@dataclass(frozen=True)
class Frame:
    """Everything in view at one time: jellyfish, and fluid particles (K, 3) m when a fluid was
    simulated (``fluid_radius`` m each)."""

    time: float
    jellyfish: list[Jellyfish]
    fluid: np.ndarray | None = None
    fluid_radius: float = 0.0


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit normals (V, 3) at the vertices of a triangle mesh, area-weighted averages of the
    normals of the faces around each vertex (outward for counter-clockwise faces)."""
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    face_normals = np.cross(b - a, c - a)  # length = twice the area: area weighting
    normals = np.zeros_like(vertices, dtype=np.float64)
    for corner in range(3):
        np.add.at(normals, faces[:, corner], face_normals)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.where(length > 0.0, length, 1.0)


def tentacle_radii(particles: int, look: Look) -> np.ndarray:
    """Radius (m) at each particle of a drawn tentacle, (P,): linear taper from the root."""
    return look.tentacle_radius * np.linspace(1.0, look.tentacle_taper, particles)


def ribbon_phase(index: int) -> float:
    """The ruffle phase (rad) of the drawn arm ``index``: golden-angle steps, so no two arms of
    a jellyfish ruffle in lockstep and the same arm keeps its phase from frame to frame."""
    return (2.399963229728653 * index) % (2.0 * np.pi)
