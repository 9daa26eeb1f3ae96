"""POV-Ray scene files for a frame, and the system ``povray`` that renders them.

World coordinates are right-handed with z up (DESIGN §3); POV-Ray's are left-handed with y up.
Swapping y and z maps one onto the other without mirroring the picture (:func:`vec`).

Looks (docs/rendering.md): the bell is a smooth ``mesh2`` with vertex normals, translucent,
glowing at final quality; every tentacle is a tapered tube made of short cones with a sphere at
each joint, all of a jellyfish's tentacles in one ``union`` (far faster to parse and trace than one
``sphere_sweep`` per tentacle); three lights after the paper's Fig. 12 (key, fill and back), fog in
the water's colour for the depth fade, and optionally the paper's room with a water tank.
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jellysim.render.frame import (
    FLUID_COLOR,
    Camera,
    Frame,
    Jellyfish,
    Look,
    tentacle_radii,
    vertex_normals,
)

INCLUDE_DIRS = (
    "/usr/share/povray-3.7/include",
    "/usr/share/povray/include",
    "/usr/local/share/povray-3.7/include",
)


@dataclass(frozen=True)
class Quality:
    """A named quality level: antialiasing, shadows, glow and ray depth."""

    name: str
    antialias: float | None  # POV-Ray's +A threshold; None: off
    all_shadows: bool  # fill and back lights cast shadows too
    glow: bool  # the bell's emission and refraction
    trace_level: int


QUALITIES = {
    "draft": Quality("draft", None, False, False, 5),
    "final": Quality("final", 0.3, True, True, 8),
}


def vec(point: Iterable[float]) -> str:
    """A world point (x, y, z), z up, as a POV-Ray vector <x, z, y> (y up, left-handed)."""
    x, y, z = (float(c) for c in point)
    return f"<{x:.6g},{z:.6g},{y:.6g}>"


def _rgb(color: Iterable[float]) -> str:
    r, g, b = (float(c) for c in color)
    return f"<{r:.4g},{g:.4g},{b:.4g}>"


def camera_block(camera: Camera, size: tuple[int, int]) -> str:
    width, height = size
    return (
        "camera {\n  perspective\n"
        f"  location {vec(camera.location)}\n"
        "  sky <0,1,0>\n"
        f"  right x*{width / height:.6g}\n"
        f"  angle {camera.angle:.6g}\n"
        f"  look_at {vec(camera.look_at)}\n}}\n"
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


def water_block(water: Iterable[float], fade_distance: float) -> str:
    """Background and fog in the water's colour: far things fade into the water."""
    color = _rgb(water)
    deep = _rgb(0.25 * np.asarray(tuple(water)))
    return (
        "sky_sphere { pigment { gradient y color_map { "
        f"[0.0 rgb {deep}] [0.5 rgb {deep}] [0.75 rgb {color}] [1.0 rgb {color}] }} "
        "scale 2 translate -1 } }\n"
        f"fog {{ fog_type 1 distance {fade_distance:.6g} color rgb {deep} }}\n"
    )


def bell_block(jelly: Jellyfish, quality: Quality) -> str:
    """The bell as a smooth mesh2 (vertex normals), translucent; glowing at final quality."""
    if jelly.bell_vertices is None or jelly.bell_faces is None:
        return ""
    vertices, faces = jelly.bell_vertices, jelly.bell_faces
    normals = vertex_normals(vertices, faces)
    look = jelly.look
    finish = "finish { ambient 0.15 diffuse 0.6 specular 0.4 roughness 0.02"
    finish += f" emission {0.6 * look.glow:.3g} }}" if quality.glow else " }"
    interior = " interior { ior 1.02 }" if quality.glow else ""
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
        "  texture { pigment { rgbt <"
        f"{look.bell_color[0]:.4g},{look.bell_color[1]:.4g},{look.bell_color[2]:.4g},"
        f"{look.bell_transparency:.3g}> }} {finish} }}{interior}",
        "}",
    ]
    return "\n".join(lines) + "\n"


def tentacles_block(jelly: Jellyfish) -> str:
    """Every tentacle as a tapered tube: cones between particles, spheres at the joints."""
    tentacles = jelly.tentacles
    if tentacles.size == 0:
        return ""
    radii = tentacle_radii(tentacles.shape[1], jelly.look)
    parts = ["union {"]
    for chain in tentacles:
        points = [vec(p) for p in chain]
        for i in range(len(points) - 1):
            parts.append(f"cone{{{points[i]},{radii[i]:.4g},{points[i + 1]},{radii[i + 1]:.4g}}}")
            if i > 0:
                parts.append(f"sphere{{{points[i]},{radii[i]:.4g}}}")
    color = _rgb(jelly.look.tentacle_color)
    parts.append(
        f"texture {{ pigment {{ rgb {color} }} "
        "finish { ambient 0.15 diffuse 0.7 specular 0.2 } }"
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
) -> str:
    """The whole POV-Ray scene of one frame. ``extent`` (m) is the size of what is framed;
    ``water`` the water's colour (default: the first jellyfish's look)."""
    if water is None:
        water = frame.jellyfish[0].look.water_color if frame.jellyfish else Look().water_color
    parts = [
        "#version 3.7;\n",
        f"global_settings {{ assumed_gamma 1.0 max_trace_level {quality.trace_level} }}\n",
        f"// jellysim frame at t = {frame.time:.6g} s\n",
        camera_block(camera, size),
        lights_block(camera, extent, quality),
    ]
    if room is None:
        parts.append(water_block(water, 6.0 * extent))
    else:
        parts.append("background { rgb <0.9,0.9,0.88> }\n")
        parts.append(room_block(room[0], room[1], water))
    for jelly in frame.jellyfish:
        parts.append(bell_block(jelly, quality))
        parts.append(tentacles_block(jelly))
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
