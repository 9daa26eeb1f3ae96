"""POV-Ray scene files for a frame, and the system ``povray`` that renders them.

World coordinates are right-handed with z up (DESIGN §3); POV-Ray's are left-handed with y up.
Swapping y and z maps one onto the other without mirroring the picture (:func:`vec`).

Looks (docs/rendering.md): the bell is a smooth ``mesh2`` with vertex normals, translucent
mesoglea with a Fresnel-like rim (the ``aoi`` pattern) and radial stripes, at final quality
glowing, refracting and holding a scattering medium; tentacles group by group, each in its own
look: a thread group's tentacles tapered tubes made of short cones with a sphere at each joint,
in one ``union`` (far faster to parse and trace than one ``sphere_sweep`` per tentacle), a
ribbon group's oral arms ruffled curtains in one ``mesh2``, hung from a manubrium (a cone);
horseshoe gonads (``look.gonads``) as tubes inside the bell;
three lights after the paper's Fig. 12 (key, fill and back); the water a ground fog for the
depth fade, with drifting marine snow and, at final quality, light shafts from above and depth
of field; optionally the paper's room with a water tank.
"""

from __future__ import annotations

import math
import shutil
import subprocess
from collections.abc import Iterable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from jellysim.render.frame import (
    FLUID_COLOR,
    Camera,
    DrawnTentacles,
    Frame,
    Jellyfish,
    Look,
    ribbon_phase,
    tentacle_radii,
    vertex_normals,
)
from jellysim.render.materials import (
    GLOW_EMISSION,
    STRIPE_PROFILE,
    STRIPE_TRANSMIT,
    arm_tissue,
    bell_material,
    bell_transmit,
    stripe_color,
    tentacle_face_color,
    tentacle_material,
    thread_look,
)

if TYPE_CHECKING:
    from jellysim.render.ribbons import RibbonMesh

INCLUDE_DIRS = (
    "/usr/share/povray-3.7/include",
    "/usr/share/povray/include",
    "/usr/local/share/povray-3.7/include",
)


@dataclass(frozen=True)
class Quality:
    """A named quality level: antialiasing, shadows, the volumetric and lens effects, ray depth."""

    name: str
    antialias: float | None  # POV-Ray's +A threshold; None: off (focal blur samples instead)
    all_shadows: bool  # fill and back lights cast shadows too
    glow: bool  # the bell's emission, refraction and glowing media inside it
    trace_level: int
    light_shafts: bool  # shafts of light from above in the water
    focal_blur: bool  # depth of field focused on the jellyfish; its samples antialias too


QUALITIES = {
    "draft": Quality("draft", None, False, False, 5, False, False),
    "final": Quality("final", None, True, True, 8, True, True),
}


def vec(point: Iterable[float]) -> str:
    """A world point (x, y, z), z up, as a POV-Ray vector <x, z, y> (y up, left-handed)."""
    x, y, z = (float(c) for c in point)
    return f"<{x:.6g},{z:.6g},{y:.6g}>"


def _rgb(color: Iterable[float]) -> str:
    r, g, b = (float(c) for c in color)
    return f"<{r:.4g},{g:.4g},{b:.4g}>"


APERTURE = 0.02  # focal blur: the aperture per metre of camera distance at depth_of_field 1
SNOW_STREAM = 0x5A0  # random streams of the water's particles and shafts, apart from --seed's
SHAFT_STREAM = 0x5AF
SHAFTS = 6  # light shafts in the tile around the camera's target


def camera_block(camera: Camera, size: tuple[int, int], focal_blur: float | None = None) -> str:
    """The camera; with ``focal_blur`` (not None), depth of field focused on ``look_at``: an
    aperture of ``focal_blur * APERTURE`` per metre of distance (a few pixels of blur at 1.5x the
    distance), 4 to 16 jittered samples a pixel, which also antialias (at ``focal_blur`` 0 the
    aperture is a pinhole's and only the antialiasing is left)."""
    width, height = size
    blur = ""
    if focal_blur is not None:
        distance = float(np.linalg.norm(camera.look_at - camera.location))
        aperture = max(focal_blur * APERTURE, 1e-4) * distance
        blur = (
            f"  aperture {aperture:.4g}\n"
            "  blur_samples 4, 16\n  confidence 0.9\n  variance 1/256\n"
            f"  focal_point {vec(camera.look_at)}\n"
        )
    return (
        "camera {\n  perspective\n"
        f"  location {vec(camera.location)}\n"
        "  sky <0,1,0>\n"
        f"  right x*{width / height:.6g}\n"
        f"  angle {camera.angle:.6g}\n"
        f"  look_at {vec(camera.look_at)}\n{blur}}}\n"
    )


def lights_block(camera: Camera, extent: float, quality: Quality) -> str:
    """Key light above and in front, fill light to the side, back light behind (Fig. 12)."""
    right, up, forward = camera.basis()
    centre = camera.look_at
    reach = 4.0 * extent
    key = centre + reach * (0.9 * up - 0.6 * forward - 0.4 * right)
    fill = centre + reach * (0.2 * up - 0.5 * forward + 0.9 * right)
    back = centre + reach * (0.6 * up + 1.0 * forward + 0.2 * right)
    shadow = "" if quality.all_shadows else " shadowless"
    return (
        f"light_source {{ {vec(key)} color rgb <1,0.98,0.95> }}\n"
        f"light_source {{ {vec(fill)} color rgb 0.45{shadow} }}\n"
        f"light_source {{ {vec(back)} color rgb 0.6{shadow} }}\n"
    )


def water_block(water: Iterable[float], fade_distance: float, camera: Camera) -> str:
    """The water: a fog in its deep colour, everywhere at and below the camera and thinning
    above it (POV-Ray's ground fog, in height above the camera's target), so things fade into
    the water with distance and the water brightens towards the surface, up to three times
    the water's colour straight up."""
    water_rgb = np.asarray(tuple(water), dtype=np.float64)
    deep = _rgb(0.25 * water_rgb)
    bright = _rgb(np.minimum(3.0 * water_rgb, 1.0))
    return (
        "sky_sphere { pigment { gradient y color_map { "
        f"[0.0 rgb {deep}] [0.5 rgb {deep}] [0.6 rgb {_rgb(water_rgb)}] [1.0 rgb {bright}] }} "
        "scale 2 translate -1 } }\n"
        f"fog {{ fog_type 2 distance {fade_distance:.6g} color rgb {deep} "
        f"fog_offset {camera.look_at[2]:.6g} fog_alt {0.08 * fade_distance:.6g} up y }}\n"
    )


def _wrap(points: np.ndarray, low: np.ndarray, period: float) -> np.ndarray:
    """Points of a world-fixed periodic tiling (period m) moved into the cube at ``low``: a point
    keeps its world place while the cube moves with the camera, until it leaves the cube and
    comes back in on the far side."""
    return low + np.mod(points - low, period)


def marine_snow_block(
    camera: Camera,
    size: tuple[int, int],
    look: Look,
    water: Iterable[float],
    seed: int,
    time: float,
) -> str:
    """``look.marine_snow`` small, dim, self-lit particles drifting slowly in the water (m/s in
    proportion to the camera distance, so they read on screen at any scale), in a world-fixed
    tiling around the camera's view: every frame has the same particles, each where its drift
    has taken it, so they neither flicker nor jump between frames."""
    if look.marine_snow <= 0:
        return ""
    _, _, forward = camera.basis()
    distance = float(np.linalg.norm(camera.look_at - camera.location))
    period = 2.2 * distance
    low = camera.look_at + 0.3 * distance * forward - 0.5 * period
    rng = np.random.default_rng([seed, SNOW_STREAM])
    count = look.marine_snow
    base = rng.uniform(0.0, period, size=(count, 3))
    drift = distance * (rng.normal(0.0, 0.006, size=(count, 3)) - np.array([0.0, 0.0, 0.008]))
    pixel = 2.0 * math.tan(math.radians(camera.angle) / 2.0) * distance / size[0]
    radii = pixel * rng.uniform(0.35, 0.9, size=count)
    brightness = rng.uniform(0.15, 0.4, size=count)
    points = _wrap(base + time * drift, low, period)
    water_rgb = np.asarray(tuple(water), dtype=np.float64)
    parts = ["union {"]
    for point, radius, bright in zip(points, radii, brightness, strict=True):
        color = water_rgb + bright * (1.0 - water_rgb)
        parts.append(f"sphere{{{vec(point)},{radius:.4g} pigment{{rgb {_rgb(color)}}}}}")
    parts.append("finish { ambient 0 diffuse 0 emission 1 } no_shadow\n}")
    return "\n".join(parts) + "\n"


def light_shafts_block(camera: Camera, look: Look, water: Iterable[float], seed: int) -> str:
    """Shafts of light from above, faked cheaply: open cylinders, vertical but for a lean
    towards the key light, whose surface is clear at the silhouette and glows face-on (the
    ``aoi`` pattern), so each reads as a soft-edged beam; bright above, fading out downwards.
    World-fixed in x and y (a tiling around the camera's target, like the snow)."""
    if look.light_shafts <= 0.0:
        return ""
    right, up, forward = camera.basis()
    distance = float(np.linalg.norm(camera.look_at - camera.location))
    period = 2.0 * distance
    centre = camera.look_at + 1.1 * distance * forward
    rng = np.random.default_rng([seed, SHAFT_STREAM])
    base = rng.uniform(0.0, period, size=(SHAFTS, 2))
    radii = distance * rng.uniform(0.05, 0.14, size=SHAFTS)
    strengths = rng.uniform(0.5, 1.0, size=SHAFTS)
    xy = _wrap(base, centre[:2] - 0.5 * period, period)
    span = 1.4 * distance
    bottom_z, top_z = camera.look_at[2] - span, camera.look_at[2] + span
    lean = -0.6 * forward - 0.4 * right  # towards the key light, horizontally
    lean[2] = 0.0
    lean *= 0.25 / max(float(np.linalg.norm(lean)), 1e-9)
    water_rgb = np.asarray(tuple(water), dtype=np.float64)
    light = 0.5 + 0.5 * water_rgb / max(float(water_rgb.max()), 1e-9)
    parts = []
    for (x, y), radius, strength in zip(xy, radii, strengths, strict=True):
        if np.dot(np.array([x, y]) - camera.location[:2], forward[:2]) < 1.2 * distance:
            continue  # in front of the jellyfish, or behind the camera
        bottom = np.array([x, y, bottom_z])
        top = bottom + (top_z - bottom_z) * (np.array([0.0, 0.0, 1.0]) + lean)
        glow = 0.3 * look.light_shafts * strength
        fade = (
            f"gradient y color_map {{ [0 rgbt <{_rgb(light)[1:-1]},1>] "
            f"[0.4 rgbt <{_rgb(light)[1:-1]},1>] "
            f"[1 rgbt <{_rgb(light)[1:-1]},{1.0 - glow:.4g}>] }} "
            f"scale {1.01 * (top[2] - bottom_z):.4g} translate y*{bottom_z:.6g}"
        )
        parts.append(
            f"cylinder {{ {vec(bottom)}, {vec(top)}, {radius:.4g} open\n"
            "  texture { pigment { aoi pigment_map { [0.5 rgbt 1] [0.6 rgbt 1] "
            f"[1 {fade}] }} }} finish {{ ambient 0 diffuse 0 emission 1 }} }}\n"
            "  no_shadow\n}"
        )
    return "\n".join(parts) + "\n" if parts else ""


FRESNEL_SAMPLES = (0.0, 0.3, 0.55, 0.75, 0.9, 1.0)  # of the way from face-on to the silhouette


def is_closed(faces: np.ndarray) -> bool:
    """Whether a triangle mesh (faces (M, 3) int) is closed: every edge in exactly two faces."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return bool(np.all(counts == 2))


def _bell_pigment(jelly: Jellyfish, transmit: float, centre: np.ndarray, lighten: float) -> str:
    """The bell's colour at one ``transmit``, lightened ``lighten`` of the way to white: plain, or
    with ``look.stripes`` radial stripes about the bell's axis through ``centre`` (a lobe's tip
    at angle 0 has one)."""
    look = jelly.look
    bell = np.asarray(bell_material(look).base_color, dtype=np.float64)
    plain = f"rgbt <{_rgb(bell + lighten * (1.0 - bell))[1:-1]},{transmit:.3g}>"
    if look.stripes <= 0:
        return plain
    stripe = np.asarray(stripe_color(look), dtype=np.float64)
    dark = (
        f"rgbt <{_rgb(stripe + lighten * (1.0 - stripe))[1:-1]},{STRIPE_TRANSMIT * transmit:.3g}>"
    )
    entries = " ".join(
        f"[{position:.3g} {dark if weight > 0.5 else plain}]" for position, weight in STRIPE_PROFILE
    )
    return f"radial frequency {look.stripes} color_map {{ {entries} }} translate {vec(centre)}"


def bell_block(jelly: Jellyfish, quality: Quality) -> str:
    """The bell as a smooth mesh2 (vertex normals) of translucent mesoglea: clear face-on and
    opaque at the silhouette (``look.rim``, a Fresnel-like falloff over the ``aoi`` pattern),
    radial stripes seen through it; at final quality glowing, refracting and, when the surface
    is closed, filled with a glowing, scattering, absorbing medium, so thick parts (the
    silhouette) glow the most and the lights soften in it."""
    if jelly.bell_vertices is None or jelly.bell_faces is None:
        return ""
    vertices, faces = jelly.bell_vertices, jelly.bell_faces
    normals = vertex_normals(vertices, faces)
    look = jelly.look
    centre = vertices.mean(axis=0)
    size = float(np.ptp(vertices, axis=0).max())
    entries = []
    for fraction in FRESNEL_SAMPLES:
        transmit, lighten = bell_transmit(look, math.cos(0.5 * math.pi * fraction))
        pigment = _bell_pigment(jelly, float(transmit), centre, float(lighten))
        # aoi: 1 face-on, 0.5 at the silhouette, 0 face-on again from behind.
        for value in sorted({0.5 * fraction, 1.0 - 0.5 * fraction}):
            entries.append((value, pigment))
    entries.sort(key=lambda entry: entry[0])
    pigment_map = " ".join(f"[{value:.4g} {pigment}]" for value, pigment in entries)
    finish = "finish { ambient 0.1 diffuse 0.3 specular 0.3 roughness 0.005"
    finish += f" emission {GLOW_EMISSION * look.glow:.3g} }}" if quality.glow else " }"
    interior, inside = "", ""
    ior = bell_material(look).ior
    if quality.glow:
        interior = f" interior {{ ior {ior:.4g} }}"
    if quality.glow and is_closed(faces):  # media need a closed surface with an inside
        inside = "  inside_vector <0,1,0>"
        bell = np.asarray(look.bell_color, dtype=np.float64)
        # Per metre, in proportion to the bell's size: the same look at any scale.
        emission = 1.5 * look.glow * bell / size
        scattering = 2.0 * bell / size
        absorption = 0.8 * (1.0 - bell) / size
        interior = (
            f" interior {{ ior {ior:.4g} media {{ method 3 intervals 1 samples 3 "
            f"emission {_rgb(emission)} scattering {{ 1, {_rgb(scattering)} extinction 0.5 }} "
            f"absorption {_rgb(absorption)} }} }}"
        )
    lines = [
        "mesh2 {",
        f"  vertex_vectors {{ {len(vertices)},",
        ",".join(vec(v) for v in vertices),
        "  }",
        f"  normal_vectors {{ {len(normals)},",
        ",".join(vec(n) for n in normals),
        "  }",
        f"  face_indices {{ {len(faces)},",
        # The y-z swap reverses the winding; POV-Ray does not cull, so keep the indices.
        ",".join(f"<{a},{b},{c}>" for a, b, c in faces),
        "  }",
        inside,
        f"  texture {{ pigment {{ aoi pigment_map {{ {pigment_map} }} }} {finish} }}{interior}",
        "}",
    ]
    return "\n".join(line for line in lines if line) + "\n"


def tentacles_block(
    jelly: Jellyfish, water: Iterable[float], quality: Quality | None = None
) -> str:
    """Every group of the jellyfish's drawn tentacles in its own look: threads through
    :func:`threads_block`, ribbons (oral arms) through :func:`ribbons_block` (glowing at a
    ``quality`` with glow)."""
    glow = quality is not None and quality.glow
    parts = []
    for group in jelly.drawn():
        if group.look.form == "ribbon":
            block = ribbons_block(jelly, group, glow)
        else:
            block = threads_block(group.positions, thread_look(jelly.look, group.look), water)
        parts.append(_named(f"tentacles {group.look.name}", block))
    return "".join(parts)


def _named(name: str, block: str) -> str:
    """``block`` (one object) after a comment line ``// object NAME`` that says which object of
    the jellyfish it is (for people and tests reading the scene); "" stays ""."""
    return f"// object {name}\n{block}" if block else ""


def threads_block(tentacles: np.ndarray, look: Look, water: Iterable[float]) -> str:
    """Tentacles (N, P, 3) m as tapered tubes in ``look``'s tentacle colour, radius and taper:
    cones between particles, spheres at the joints, one ``union``. Slightly translucent, faked:
    the tubes are opaque, their colour mixed ``look.tentacle_transparency`` of the way towards
    the deep water's face-on and pure at their edges (the ``aoi`` pattern), as a clear tube in
    dark water looks. Traced transparency costs six times as much at 300 tentacles
    (docs/performance.md) and cannot be seen at 2 to 3 pixels a tentacle."""
    if tentacles.size == 0:
        return ""
    radii = tentacle_radii(tentacles.shape[1], look)
    parts = ["union {"]
    for chain in tentacles:
        points = [vec(p) for p in chain]
        for i in range(len(points) - 1):
            parts.append(f"cone{{{points[i]},{radii[i]:.4g},{points[i + 1]},{radii[i + 1]:.4g}}}")
            if i > 0:
                parts.append(f"sphere{{{points[i]},{radii[i]:.4g}}}")
    # The deep water behind is the scene's (a school's first jellyfish's), not this one's.
    red, green, blue = (float(c) for c in water)
    look = replace(look, water_color=(red, green, blue))
    clear = f"rgb {_rgb(tentacle_face_color(look))}"
    edge = f"rgb {_rgb(tentacle_material(look).base_color)}"
    parts.append(
        f"texture {{ pigment {{ aoi color_map {{ [0 {clear}] [0.3 {clear}] [0.5 {edge}] "
        f"[0.7 {clear}] [1 {clear}] }} }} "
        "finish { ambient 0.15 diffuse 0.7 specular 0.3 roughness 0.02 } }"
    )
    parts.append("}")
    return "\n".join(parts) + "\n"


def ribbons_block(jelly: Jellyfish, group: DrawnTentacles, glow: bool) -> str:
    """A ribbon group (oral arms) as one ``mesh2`` of ruffled curtains in the group's colour and
    the bell's tissue (:func:`jellysim.render.ribbons.povray_ribbons`)."""
    from jellysim.render.ribbons import povray_ribbons

    return povray_ribbons(arm_meshes(jelly, group), group.look.color, arm_tissue(jelly.look), glow)


def arm_meshes(jelly: Jellyfish, group: DrawnTentacles) -> list[RibbonMesh]:
    """The ruffled meshes of a ribbon group's arms: each one's width starting radially out from
    the bell's axis (vertical through ``jelly.centre``; the arm's own root when there is none) at
    its root, its ruffles shifted by :func:`ribbon_phase` of its drawn index."""
    from jellysim.render.ribbons import ribbon_mesh

    look = group.look
    axis = jelly.centre
    meshes = []
    for row, chain in enumerate(group.positions):
        outward = chain[0] - (chain[0] if axis is None else axis)
        outward[2] = 0.0
        meshes.append(
            ribbon_mesh(
                chain,
                outward,
                look.ribbon_width,
                look.taper,
                look.ruffles,
                look.ruffle_depth,
                phase=ribbon_phase(group.first + row),
            )
        )
    return meshes


def manubrium_block(jelly: Jellyfish, glow: bool) -> str:
    """The manubrium: a cone in the bell's tissue and colour from the subumbrella's centre down
    to the oral arms' roots (docs/rendering.md, "Oral arms")."""
    stalk = jelly.manubrium
    if stalk is None:
        return ""
    from jellysim.render.ribbons import ribbon_pigment

    look = jelly.look
    finish = "finish { ambient 0.1 diffuse 0.4 specular 0.3 roughness 0.01"
    finish += f" emission {GLOW_EMISSION * look.glow:.3g} }}" if glow else " }"
    return (
        f"cone {{ {vec(stalk.top)}, {stalk.top_radius:.4g}, "
        f"{vec(stalk.bottom)}, {stalk.bottom_radius:.4g}\n"
        f"  texture {{ pigment {{ {ribbon_pigment(look.bell_color, look)} }} {finish} }}\n}}\n"
    )


GONAD_GLOW = 1.0  # the gonads' emission at final quality, relative to the bell's (own colour)
GONAD_EDGE = 0.4  # a gonad's outline: its colour moved this far towards white (soft tissue)


def gonads_block(jelly: Jellyfish, glow: bool) -> str:
    """The horseshoe gonads (:func:`jellysim.render.pipeline.gonads`): tubes of cones with a
    sphere at each joint and end, one ``union`` in ``look.gonad_color``, lighter at their
    outline (the ``aoi`` pattern, a soft edge), glowing a little at a quality with glow; seen
    through the translucent bell. Opaque: translucent gonads inside the bell's medium cost a
    third more time a final frame for no visible gain (docs/performance.md). Nothing when the
    frame has none."""
    if jelly.gonads is None:
        return ""
    radius = f"{jelly.gonads.radius:.4g}"
    parts = ["union {"]
    for path in jelly.gonads.paths:
        points = [vec(p) for p in path]
        parts.extend(f"sphere{{{point},{radius}}}" for point in points)
        parts.extend(
            f"cone{{{points[i]},{radius},{points[i + 1]},{radius}}}" for i in range(len(points) - 1)
        )
    look = jelly.look
    color = np.asarray(look.gonad_color, dtype=np.float64)
    lighter = color + GONAD_EDGE * (1.0 - color)
    face, edge = f"rgb {_rgb(color)}", f"rgb {_rgb(lighter)}"
    finish = "finish { ambient 0.2 diffuse 0.6 specular 0.1 roughness 0.1"
    finish += f" emission {GONAD_GLOW * GLOW_EMISSION * look.glow:.3g} }}" if glow else " }"
    parts.append(
        f"texture {{ pigment {{ aoi color_map {{ [0 {face}] [0.3 {face}] [0.5 {edge}] "
        f"[0.7 {face}] [1 {face}] }} }} {finish} }}"
    )
    parts.append("}")
    return "\n".join(parts) + "\n"


def fluid_block(frame: Frame, style: str) -> str:
    """Fluid particles as small spheres, or as one blobby surface over them."""
    if frame.fluid is None or frame.fluid.size == 0:
        return ""
    radius = frame.fluid_radius
    red, green, blue = FLUID_COLOR
    color = f"texture {{ pigment {{ rgbt <{red},{green},{blue},0.6> }} finish {{ specular 0.5 }} }}"
    if style == "surface":
        body = "".join(f"sphere{{{vec(p)},{2.0 * radius:.4g},1}}" for p in frame.fluid)
        return f"blob {{ threshold 0.6 {body} {color} }}\n"
    body = "".join(f"sphere{{{vec(p)},{radius:.4g}}}" for p in frame.fluid)
    return f"union {{ {body} {color} }}\n"


def room_box(low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The tank's inner corners around what swims in it (``low``, ``high`` (3,) m): a margin of
    a fifth of the horizontal size at the sides, a tenth above and below."""
    size = high - low
    side = 0.2 * max(size[0], size[1])
    margin = np.array([side, side, 0.1 * size[2] + side / 2])
    return low - margin, high + margin


def room_block(tank_low: np.ndarray, tank_high: np.ndarray, water: Iterable[float]) -> str:
    """The paper's Fig. 12 set: a glass tank of water (corners ``tank_low``, ``tank_high``, m)
    on a tiled floor in front of a wall."""
    size = tank_high - tank_low
    scale = float(size.max())
    glass = 0.005 * scale
    floor = tank_low[2] - glass
    tile = max(float(max(size[0], size[1])) / 4.0, 1e-3)
    # Water tints what is seen through it: a light filter towards the water's hue.
    hue = np.asarray(tuple(water), dtype=np.float64)
    tint = 0.7 + 0.3 * hue / max(float(hue.max()), 1e-9)
    return (
        f"plane {{ y, {floor:.6g} pigment {{ checker rgb 0.75 rgb 0.5 scale {tile:.4g} }} "
        "finish { diffuse 0.8 } }\n"
        f"plane {{ z, {tank_high[1] + 2.0 * scale:.6g} pigment {{ rgb <0.85,0.83,0.78> }} }}\n"
        f"box {{ {vec(tank_low - glass)}, {vec(tank_high + glass)} hollow "
        f"texture {{ pigment {{ rgbf <{tint[0]:.3g},{tint[1]:.3g},{tint[2]:.3g},0.92> }} "
        "finish { specular 0.6 roughness 0.01 reflection 0.04 } } interior { ior 1.0 } }\n"
    )


def scene_text(
    frame: Frame,
    camera: Camera,
    size: tuple[int, int],
    quality: Quality,
    extent: float,
    room: tuple[np.ndarray, np.ndarray] | None = None,
    fluid_style: str = "spheres",
    water: Iterable[float] | None = None,
    seed: int = 0,
) -> str:
    """The whole POV-Ray scene of one frame. ``extent`` (m) is the size of what is framed;
    ``water`` the water's colour (default: the first jellyfish's look); ``seed`` places the
    water's particles and light shafts. The same arguments give the same text."""
    look = frame.jellyfish[0].look if frame.jellyfish else Look()
    if water is None:
        water = look.water_color
    focal_blur = look.depth_of_field if quality.focal_blur else None
    parts = [
        "#version 3.7;\n",
        f"global_settings {{ assumed_gamma 1.0 max_trace_level {quality.trace_level} }}\n",
        f"// jellysim frame at t = {frame.time:.6g} s\n",
        camera_block(camera, size, focal_blur),
        lights_block(camera, extent, quality),
    ]
    if room is not None:
        parts.append("background { rgb <0.9,0.9,0.88> }\n")
        parts.append(room_block(room[0], room[1], water))
    else:
        parts.append(water_block(water, 6.0 * extent, camera))
        # The water's particles and light shafts, not among simulated fluid particles, which
        # they would be mistaken for.
        if frame.fluid is None or frame.fluid.size == 0:
            parts.append(marine_snow_block(camera, size, look, water, seed, frame.time))
            if quality.light_shafts:
                parts.append(light_shafts_block(camera, look, water, seed))
    for jelly in frame.jellyfish:
        parts.append(_named("bell", bell_block(jelly, quality)))
        parts.append(_named("gonads", gonads_block(jelly, quality.glow)))
        parts.append(_named("manubrium", manubrium_block(jelly, quality.glow)))
        parts.append(tentacles_block(jelly, water, quality))
    parts.append(fluid_block(frame, fluid_style))
    return "".join(parts)


def find_povray() -> str | None:
    return shutil.which("povray")


def include_args() -> list[str]:
    return [f"+L{folder}" for folder in INCLUDE_DIRS if Path(folder).is_dir()]


def render_file(
    povray: str, scene: Path, image: Path, size: tuple[int, int], quality: Quality, threads: int
) -> None:
    """Render ``scene`` to the PNG ``image`` (written under a temporary name, then renamed, so
    an interrupted render leaves no half image). Raises RuntimeError with POV-Ray's message."""
    width, height = size
    partial = image.with_name(image.stem + ".part.png")
    args = [
        povray,
        "-D",  # no display
        f"+I{scene}",
        f"+O{partial}",
        f"+W{width}",
        f"+H{height}",
        "+FN",
        f"+WT{threads}",
        "-GA",  # no banner, statistics or warnings on the console
        "+GF",  # but fatal errors
        *include_args(),
    ]
    if quality.antialias is not None:
        args += [f"+A{quality.antialias}", "+AM2", "+R3"]
    done = subprocess.run(args, capture_output=True, text=True, check=False)
    if done.returncode != 0 or not partial.is_file():
        partial.unlink(missing_ok=True)
        message = (done.stderr or done.stdout).strip().splitlines()[-3:]
        raise RuntimeError(f"povray failed on {scene.name}: {' | '.join(message)}")
    partial.replace(image)
