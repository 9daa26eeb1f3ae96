"""Import a jellysim USD stage or glTF part into Blender, ready to render.

``jellysim export DIR --format usd`` and ``--format gltf`` write this script as
``import_into_blender.py`` next to the stage or the glTF parts. It imports a USD stage (a path
ending in anything but ``.glb`` or ``.gltf``) in a Blender that reads USD: the official builds
from blender.org, or the ``bpy`` module from PyPI (``pip install bpy``, Blender as a Python
module); Debian's and Ubuntu's own ``blender`` packages are built without USD, and there the
script says so and exits with status 2. A glTF part (``.glb``, ``.gltf``) imports in any Blender
with its bundled glTF 2.0 add-on::

    blender --background --python import_into_blender.py -- FILE \\
        [--render OUT.png] [--frames A:B] [--size WxH] [--samples N] [--save FILE.blend]
    python import_into_blender.py FILE [same options]      # a Python with bpy

(FILE: ``STAGE.usdc`` or ``NAME_partNNN.glb``; without ``--background`` Blender opens with the
file set up), or open it in Blender's text editor and press Run Script (it imports the file it
was exported with, next to it: the stage, or the first glTF part). In an unsaved file (the
start-up scene) it first removes every object (the default cube, light and camera); a saved
file's objects are kept. It imports the file (``bpy.ops.wm.usd_import``, or
``bpy.ops.import_scene.gltf`` with the file's fps as the scene's, its keyframes then put on the
exported frame numbers), gives each object (the bell, each tentacle group, the fluid) a
Principled BSDF built from the material the exporter resolved for it from the scene's
``[look]``, the one every jellysim renderer and export draws it in (:func:`material_parameters`),
colours the world as the water, adds a camera that follows the jellyfish as
``jellysim render --camera follow`` does, a key light and a fill light that moves with the
camera, sets the frame range, frame step, fps and resolution from the file and Cycles as the
render engine; then ``--save`` saves the .blend and ``--render`` renders frames to PNG (the
first exported frame, or those of ``--frames`` A to B-1: one frame to OUT.png itself, several to
OUT_NNNNN.png). Any failure is one line on stderr and exit status 2.

What it needs of the file (materials, water colour, frame range, bounds, the renderers' camera
direction, field of view and path) the exporter writes into the stage's layer metadata
(``customLayerData``, key ``jellysim``) or the glTF scene's ``extras`` (key ``jellysim``) and,
for a Blender whose Python lacks USD's ``pxr`` module (the ``bpy`` module), into
``EMBEDDED_SETTINGS`` below. Everything but
:func:`run` and its helpers is plain Python on plain values; ``bpy`` and ``pxr`` are imported
only inside the functions that need them, so the file imports (and is tested) without Blender.
It imports nothing of jellysim.
"""

from __future__ import annotations

import argparse
import json
import math
import struct
import sys
from pathlib import Path
from typing import Any

SCRIPT = "import_into_blender.py"
METADATA_KEY = "jellysim"  # the stage layer's customLayerData key, the glTF scene's extras key
GLTF_SUFFIXES = (".glb", ".gltf")  # a glTF file; any other path is a USD stage
RESOLUTION = (1920, 1080)  # pixels
SAMPLES = 64  # Cycles samples a pixel (denoised)
FRAMING_MARGIN = 1.08  # as jellysim render: this much beyond the nearest distance that fits
EMBEDDED_SETTINGS: dict[str, Any] | None = None  # the exporter writes the stage's settings here

VECTORS = (
    "bounds_min",
    "bounds_max",
    "view_direction",
    "camera_origin",
    "camera_velocity",
    "camera_half",
)
COLORS = ("water_color",)
NUMBERS = ("fps", "tentacle_radius", "field_of_view")
INTEGERS = ("first_frame", "last_frame", "frame_step")
MATERIAL_COLORS = ("base_color", "emissive")  # of each object's material: linear RGB
MATERIAL_NUMBERS = ("opacity", "roughness", "ior")
NO_USD = (
    "Blender {version} was built without USD support (as Debian's and Ubuntu's blender "
    "packages are): use an official build from blender.org, or the bpy module (pip install bpy)"
)


class ScriptError(Exception):
    """A failure the script reports in one line (bad arguments, a missing stage, a Blender
    without USD)."""


def is_gltf(path: str | Path) -> bool:
    """Whether ``path`` names a glTF file (``.glb``, ``.gltf``) rather than a USD stage."""
    return Path(path).suffix.lower() in GLTF_SUFFIXES


def _material_settings(name: str, material: Any) -> dict[str, Any]:
    """One object's material (``materials[name]`` of the settings) as plain values; raises
    ScriptError naming what is missing or malformed."""
    try:
        settings: dict[str, Any] = {k: [float(v) for v in material[k]] for k in MATERIAL_COLORS}
        settings.update({k: float(material[k]) for k in MATERIAL_NUMBERS})
    except (KeyError, TypeError, ValueError):
        raise ScriptError(
            f"the file's jellysim settings have no whole material for '{name}' (export it again "
            "with this jellysim)"
        ) from None
    if any(len(settings[k]) != 3 for k in MATERIAL_COLORS):
        raise ScriptError(f"the file's jellysim settings give '{name}' a colour not of 3 values")
    return settings


def settings_from_metadata(metadata: dict[str, Any]) -> dict[str, Any]:
    """The stage's ``customLayerData['jellysim']`` (or the glTF scene's ``extras['jellysim']``)
    as plain Python values (lists of floats for vectors and colours, ``materials`` a dict of
    each object's material by prim name); raises ScriptError naming a missing key."""
    settings: dict[str, Any] = {}
    for key in (*VECTORS, *COLORS, *NUMBERS, *INTEGERS, "stage_file", "materials"):
        if key not in metadata:
            raise ScriptError(
                f"the file's jellysim settings lack '{key}' (export it again with this jellysim)"
            )
    for key in (*VECTORS, *COLORS):
        settings[key] = [float(v) for v in metadata[key]]
    for key in NUMBERS:
        settings[key] = float(metadata[key])
    for key in INTEGERS:
        settings[key] = int(metadata[key])
    settings["stage_file"] = str(metadata["stage_file"])
    materials = metadata["materials"]
    if not hasattr(materials, "items"):
        raise ScriptError("the file's jellysim settings have 'materials' that is not a table")
    settings["materials"] = {
        str(name): _material_settings(str(name), material) for name, material in materials.items()
    }
    return settings


def read_stage_settings(stage_path: str | Path) -> dict[str, Any]:
    """Settings read from the stage's metadata with USD's ``pxr`` (in usd-core, and in
    Blender builds that ship USD's Python module)."""
    from pxr import Sdf

    layer = Sdf.Layer.FindOrOpen(str(stage_path))
    if layer is None:
        raise ScriptError(f"cannot open the USD stage '{stage_path}'")
    metadata = dict(layer.customLayerData).get(METADATA_KEY)
    if metadata is None:
        raise ScriptError(f"'{stage_path}' carries no jellysim metadata (export it again)")
    return settings_from_metadata(dict(metadata))


def read_gltf_settings(path: str | Path) -> dict[str, Any]:
    """Settings read from a glTF file's scene ``extras['jellysim']`` (plain JSON: a ``.glb``'s
    JSON chunk, which comes first, or a ``.gltf``); raises ScriptError for a file that is not
    glTF or carries no jellysim settings."""
    with open(path, "rb") as stream:
        head = stream.read(20)
        if head[:4] == b"glTF":  # GLB: header (magic, version, length), then the JSON chunk
            if len(head) < 20 or head[16:20] != b"JSON":
                raise ScriptError(f"'{path}' is not a binary glTF file (no JSON chunk)")
            (length,) = struct.unpack("<I", head[12:16])
            text = stream.read(length)
        else:
            text = head + stream.read()
    try:
        document = json.loads(text)
        scene = document["scenes"][document.get("scene", 0)]
        metadata = scene.get("extras", {}).get(METADATA_KEY)
    except (ValueError, UnicodeDecodeError, KeyError, IndexError, TypeError, AttributeError):
        raise ScriptError(f"'{path}' is not a glTF file with a scene") from None
    if not isinstance(metadata, dict):
        raise ScriptError(f"'{path}' carries no jellysim settings (export it again)")
    return settings_from_metadata(metadata)


def load_settings(stage_path: str | Path) -> dict[str, Any]:
    """The file's settings: a glTF file's own; a stage's where ``pxr`` imports, else the copy
    embedded when the stage is the one this script was exported with."""
    if is_gltf(stage_path):
        return read_gltf_settings(stage_path)
    try:
        return read_stage_settings(stage_path)
    except ImportError:
        if EMBEDDED_SETTINGS is None or Path(stage_path).name != EMBEDDED_SETTINGS["stage_file"]:
            raise ScriptError(
                f"this Python has no USD module (pxr) to read '{stage_path}' with: run the "
                f"{SCRIPT} exported beside that stage"
            ) from None
        return settings_from_metadata(EMBEDDED_SETTINGS)


def script_arguments(argv: list[str], script: str | Path) -> list[str]:
    """The script's own arguments: those after ``--`` (``blender --python SCRIPT -- ...``),
    those after the script (``python SCRIPT ...``), else none."""
    if "--" in argv:
        return argv[argv.index("--") + 1 :]
    if argv and Path(argv[0]).name == Path(script).name:
        return argv[1:]
    return []


def from_command_line(argv: list[str], script: str | Path) -> bool:
    """Whether the script was named on the command line (Blender's ``--python``, or Python's),
    rather than run from Blender's text editor."""
    before = argv[: argv.index("--")] if "--" in argv else argv
    return any(Path(a).name == Path(script).name for a in before)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> Any:  # one line, raised rather than printed with usage
        raise ScriptError(message)


def _frame_range(text: str) -> tuple[int, int]:
    first, colon, stop = text.partition(":")
    try:
        return int(first), int(stop)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}': expected A:B, e.g. 0:10") from None


def _size(text: str) -> tuple[int, int]:
    width, _, height = text.lower().partition("x")
    try:
        size = int(width), int(height)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"'{text}': expected WxH in pixels, e.g. 640x480"
        ) from None
    if min(size) < 4 or max(size) > 16384:
        raise argparse.ArgumentTypeError(f"'{text}': width and height from 4 to 16384 pixels")
    return size


def _samples(text: str) -> int:
    try:
        samples = int(text)
    except ValueError:
        samples = 0
    if samples < 1:
        raise argparse.ArgumentTypeError(f"'{text}': expected a whole number of at least 1")
    return samples


def parse_arguments(args: list[str]) -> argparse.Namespace:
    """The script's options (raises ScriptError with one line on a bad one)."""
    parser = _Parser(
        prog=SCRIPT,
        description="Import a jellysim USD stage or glTF part into Blender, ready to render.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument(
        "stage",
        nargs="?",
        type=Path,
        help="the USD stage or glTF part, .glb or .gltf (default: the file this script was "
        "exported with, beside it)",
    )
    parser.add_argument("--render", type=Path, metavar="OUT.png", help="render frames to PNG")
    parser.add_argument(
        "--frames",
        type=_frame_range,
        metavar="A:B",
        help="with --render: frames A to B-1 (OUT_NNNNN.png each); default the first frame",
    )
    parser.add_argument("--size", type=_size, default=RESOLUTION, metavar="WxH", help="pixels")
    parser.add_argument("--samples", type=_samples, default=SAMPLES, help="Cycles samples")
    parser.add_argument("--save", type=Path, metavar="FILE.blend", help="save the scene")
    options = parser.parse_args(args)
    if options.render is not None and options.render.suffix.lower() != ".png":
        raise ScriptError(f"--render {options.render}: expected a path ending in .png")
    if options.frames is not None and options.render is None:
        raise ScriptError("--frames chooses the frames --render renders: add --render OUT.png")
    if options.save is not None and options.save.suffix.lower() != ".blend":
        raise ScriptError(f"--save {options.save}: expected a path ending in .blend")
    return options


def stage_path(stage: Path | None, script: str | Path) -> Path:
    """The file to import: ``stage``, else the file this script was exported with (the stage,
    or the first glTF part), next to the script; raises ScriptError when there is none."""
    if stage is None:
        if EMBEDDED_SETTINGS is None:
            raise ScriptError(f"name the file: blender --python {SCRIPT} -- STAGE.usdc")
        stage = Path(script).resolve().parent / str(EMBEDDED_SETTINGS["stage_file"])
    if not stage.is_file():
        raise ScriptError(f"no {'glTF file' if is_gltf(stage) else 'USD stage'} at '{stage}'")
    return stage.resolve()


def frames_to_render(settings: dict[str, Any], frames: tuple[int, int] | None) -> list[int]:
    """The exported frames (time codes) in ``frames`` = (A, B), A to B-1; the first exported
    frame when ``frames`` is None. Raises ScriptError when none is exported."""
    first, last, step = settings["first_frame"], settings["last_frame"], settings["frame_step"]
    exported = range(first, last + 1, step)
    if frames is None:
        return [first]
    chosen = [f for f in range(*frames) if f in exported]
    if not chosen:
        raise ScriptError(
            f"--frames {frames[0]}:{frames[1]}: the file has frames {first} to {last}"
            + (f" every {step}" if step > 1 else "")
        )
    return chosen


def render_paths(out: Path, frames: list[int]) -> list[Path]:
    """Where each rendered frame goes: ``out`` itself for one frame, else ``out``'s name with
    the frame number (five digits) before ``.png``."""
    if len(frames) == 1:
        return [out]
    return [out.with_name(f"{out.stem}_{f:05d}{out.suffix}") for f in frames]


def _unit(vector: list[float]) -> list[float]:
    length = math.sqrt(sum(v * v for v in vector))
    if length == 0.0:
        raise ScriptError("a zero direction")
    return [v / length for v in vector]


def _cross(a: list[float], b: list[float]) -> list[float]:
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _dot(a: list[float], b: list[float]) -> float:
    return sum(x * y for x, y in zip(a, b, strict=True))


def camera_target(settings: dict[str, Any], frame: float) -> list[float]:
    """The point (m) the camera looks at in ``frame`` (a time code): on the straight line
    through the jellyfish's centres, as ``jellysim render --camera follow`` aims."""
    origin, velocity = settings["camera_origin"], settings["camera_velocity"]
    return [o + frame * v for o, v in zip(origin, velocity, strict=True)]


def camera_distance(
    half: list[float], direction: list[float], field_of_view: float, aspect: float
) -> float:
    """How far back (m) the camera stands from its target, as ``jellysim render`` places it:
    :data:`FRAMING_MARGIN` times the nearest distance at which every corner of the box of
    half-size ``half`` (m) about the target projects inside a picture ``field_of_view``
    degrees wide, ``aspect`` = width / height, seen along ``direction`` with z up."""
    forward = _unit(direction)
    right = _unit(_cross(forward, [0.0, 0.0, 1.0]))
    up = _cross(right, forward)
    tan_h = math.tan(math.radians(field_of_view) / 2.0)
    tan_v = tan_h / aspect
    needed = -math.inf
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            for sz in (-1.0, 1.0):
                offset = [sx * half[0], sy * half[1], sz * half[2]]
                depth = _dot(offset, forward)
                needed = max(
                    needed,
                    abs(_dot(offset, right)) / tan_h - depth,
                    abs(_dot(offset, up)) / tan_v - depth,
                )
    return FRAMING_MARGIN * needed


def camera_placement(settings: dict[str, Any], aspect: float) -> dict[str, Any]:
    """The following camera for a picture of ``aspect`` = width / height: its location (m) at
    the first and the last exported frame (it moves on a straight line at constant speed in
    between), the view direction (unit), clip distances (m) and the horizontal angle
    (radians)."""
    view = _unit(settings["view_direction"])
    distance = camera_distance(settings["camera_half"], view, settings["field_of_view"], aspect)
    radius = math.sqrt(sum(h * h for h in settings["camera_half"]))

    def location(frame: int) -> list[float]:
        return [t - distance * v for t, v in zip(camera_target(settings, frame), view, strict=True)]

    return {
        "first": location(settings["first_frame"]),
        "last": location(settings["last_frame"]),
        "direction": view,
        "distance": distance,
        "clip_start": max(1e-4, 0.01 * (distance - radius)),
        "clip_end": 2.0 * (distance + radius),
        "angle": math.radians(settings["field_of_view"]),
    }


def camera_rotation(direction: list[float]) -> list[float]:
    """Blender Euler XYZ angles (radians) turning a camera (which looks along its local -z, its
    up +y) to look along ``direction`` with no roll in a z-up world."""
    dx, dy, dz = _unit(direction)
    return [math.acos(max(-1.0, min(1.0, -dz))), 0.0, math.atan2(-dx, dy)]


def light_rig(half: list[float], distance: float) -> list[dict[str, Any]]:
    """A key light from above (a sun, as daylight through water) and a soft fill (an area
    light) beside the camera, up and to the left, shining along its view: placed in the
    camera's frame (local x right, y up, -z the view), so it moves with the camera. ``half``
    (m) is the framed box's half-size, ``distance`` (m) the camera's from its target."""
    size = max(2.0 * math.sqrt(sum(h * h for h in half)), 1e-3)
    return [
        {
            "name": "jellysim key",
            "type": "SUN",
            "rotation": [math.radians(20.0), 0.0, math.radians(30.0)],
            "energy": 1.0,  # W/m2: a white surface facing it about white
        },
        {
            "name": "jellysim fill",
            "type": "AREA",
            "camera_offset": [-0.5 * distance, 0.3 * distance, 0.0],
            "energy": 10.0 * distance * distance,  # W: a softer light than the key
            "size": size,
        },
    ]


def bsdf_parameters(material: dict[str, Any]) -> dict[str, Any]:
    """Principled BSDF inputs of one object's material (plain values, as in the settings): its
    base colour; its opacity as ``alpha`` and the rest, ``1 - opacity``, as transmission (a
    translucent material blended in EEVEE); its roughness; its emission as the emission colour
    at strength 1; its ior."""
    opacity = material["opacity"]
    return {
        "base_color": [*material["base_color"], 1.0],
        "alpha": opacity,
        "transmission": 1.0 - opacity,
        "roughness": material["roughness"],
        "emission_color": [*material["emissive"], 1.0],
        "emission_strength": 1.0,
        "ior": material["ior"],
        "blend": opacity < 1.0,
    }


def material_parameters(settings: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Principled BSDF inputs per imported prim (Bell, Tentacles or each tentacle group's
    prim, Fluid; :func:`bsdf_parameters` of its material in the settings) and the world
    colour."""
    parameters = {name: bsdf_parameters(m) for name, m in settings["materials"].items()}
    parameters["World"] = {"color": [*settings["water_color"], 1.0], "strength": 1.0}
    return parameters


def render_settings(
    settings: dict[str, Any], resolution: tuple[int, int] = RESOLUTION
) -> dict[str, Any]:
    """Blender scene settings: frame range and step (the stage's time codes are frame
    indices), fps as Blender's integer ``fps`` over ``fps_base``, and the resolution."""
    fps = settings["fps"]
    whole = max(1, round(fps))
    return {
        "frame_start": settings["first_frame"],
        "frame_end": settings["last_frame"],
        "frame_step": settings["frame_step"],
        "fps": whole,
        "fps_base": whole / fps,
        "resolution_x": resolution[0],
        "resolution_y": resolution[1],
    }


def curve_bevel_depth(point_radius: float, tentacle_radius: float) -> float:
    """Bevel depth (m) of a curve object as Blender before 4.2 imports USD curves: Blender
    scales the bevel by each point's radius, which the importer sets from the curve widths (m);
    where it left the default 1, the bevel itself carries the scene's tentacle radius."""
    return tentacle_radius if abs(point_radius - 1.0) < 1e-9 else 1.0


def _set_input(node: Any, names: tuple[str, ...], value: Any) -> None:
    """Set the first of ``names`` that the node has (socket names differ across Blender
    versions: 'Emission Color' in 4, 'Emission' in 3)."""
    for name in names:
        if name in node.inputs:
            node.inputs[name].default_value = value
            return


def _material(name: str, parameters: dict[str, Any]) -> Any:
    import bpy

    material = bpy.data.materials.new(f"jellysim {name}")
    material.use_nodes = True
    shader = material.node_tree.nodes.get("Principled BSDF")
    _set_input(shader, ("Base Color",), parameters["base_color"])
    _set_input(shader, ("Alpha",), parameters["alpha"])
    _set_input(shader, ("Roughness",), parameters["roughness"])
    _set_input(shader, ("Transmission Weight", "Transmission"), parameters["transmission"])
    _set_input(shader, ("Emission Color", "Emission"), parameters["emission_color"])
    _set_input(shader, ("Emission Strength",), parameters["emission_strength"])
    _set_input(shader, ("IOR",), parameters["ior"])
    if parameters["blend"]:
        if hasattr(material, "surface_render_method"):  # EEVEE Next (Blender 4.2 and later)
            material.surface_render_method = "BLENDED"
        else:
            material.blend_method = "BLEND"
    return material


def _fcurves(action: Any) -> list[Any]:
    """An action's F-curves: ``action.fcurves`` before Blender 5, its layers' channel bags
    (slotted actions) from 4.4 on."""
    if hasattr(action, "layers") and action.layers:
        return [
            curve
            for layer in action.layers
            for strip in layer.strips
            for bag in strip.channelbags
            for curve in bag.fcurves
        ]
    return list(getattr(action, "fcurves", ()))


def _clear_start_up_scene(bpy: Any) -> None:
    """Remove every object of an unsaved file (the start-up scene's cube, light and camera, or
    whatever a custom start-up file holds) and the data they leave unused; a saved file is the
    user's work and keeps its objects."""
    if bpy.data.filepath:
        print(f"{SCRIPT}: importing into {bpy.data.filepath}, keeping its objects", file=sys.stderr)
        return
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj, do_unlink=True)
    for collection in (bpy.data.meshes, bpy.data.lights, bpy.data.cameras, bpy.data.materials):
        for block in list(collection):
            if block.users == 0:
                collection.remove(block)


def _import_stage(bpy: Any, stage: Path) -> list[Any]:
    """The objects the stage's import adds to the scene."""
    before = set(bpy.data.objects)
    try:
        outcome = bpy.ops.wm.usd_import(filepath=str(stage), set_frame_range=True)
    except RuntimeError as error:
        raise ScriptError(f"Blender could not import '{stage}': {_first_line(error)}") from None
    imported = [o for o in bpy.data.objects if o not in before]
    if "FINISHED" not in outcome or not imported:
        raise ScriptError(f"Blender imported nothing from '{stage}'")
    return imported


def keyframe_frames(keys: list[float], fps: float, import_fps: float) -> list[float]:
    """Blender frames of keyframes that Blender's glTF importer placed at ``keys`` (frames at
    ``import_fps``, time x frame rate): time x ``fps``, rounded to the frame number it stands for
    (the file's times are frame / fps in float32)."""
    return [float(round(key * fps / import_fps)) for key in keys]


def part_object_prim(object_name: str, prims: list[str]) -> str | None:
    """The prim name (``Bell``, ``Tentacles_NAME``, ``Fluid``) among ``prims`` that an imported
    object stands for: the USD prim's (``Bell``, ``Bell.001``) or the glTF node's (``bell``,
    ``tentacles_oral-arms``), case and ``-`` aside; the longest match, so a group's
    ``Tentacles_arms`` before ``Tentacles``."""
    name = object_name.replace("-", "_").lower()
    for prim in sorted(prims, key=len, reverse=True):
        if name.startswith(prim.lower()):
            return prim
    return None


def _retime_gltf_keys(actions: list[Any], fps: float, import_fps: float) -> None:
    """Put the keyframes of the actions the glTF import made on the exported frame numbers
    (:func:`keyframe_frames`), their handles moved with them."""
    for action in actions:
        for curve in _fcurves(action):
            points = curve.keyframe_points
            co, left, right = ([0.0] * (2 * len(points)) for _ in range(3))
            points.foreach_get("co", co)
            points.foreach_get("handle_left", left)
            points.foreach_get("handle_right", right)
            frames = keyframe_frames(co[0::2], fps, import_fps)
            shift = [f - x for f, x in zip(frames, co[0::2], strict=True)]
            co[0::2] = frames
            left[0::2] = [x + d for x, d in zip(left[0::2], shift, strict=True)]
            right[0::2] = [x + d for x, d in zip(right[0::2], shift, strict=True)]
            points.foreach_set("co", co)
            points.foreach_set("handle_left", left)
            points.foreach_set("handle_right", right)
            curve.update()


def _import_gltf(bpy: Any, path: Path, settings: dict[str, Any]) -> list[Any]:
    """The objects the glTF part's import adds to the scene, its animation on the exported
    frame numbers: Blender's importer keys a time t at frame t x the scene's frame rate
    (``render.fps * render.fps_base`` in its code), so the scene plays at the part's fps (whole,
    ``fps_base`` 1) while it imports, and the keys are then retimed exactly."""
    if not hasattr(bpy.ops.import_scene, "gltf"):
        raise ScriptError("this Blender has no glTF importer: enable the glTF 2.0 add-on")
    scene = bpy.context.scene
    frame = render_settings(settings)
    scene.frame_start, scene.frame_end = frame["frame_start"], frame["frame_end"]
    scene.render.fps, scene.render.fps_base = frame["fps"], 1.0
    objects, actions = set(bpy.data.objects), set(bpy.data.actions)
    try:
        outcome = bpy.ops.import_scene.gltf(filepath=str(path))
    except RuntimeError as error:
        raise ScriptError(f"Blender could not import '{path}': {_first_line(error)}") from None
    imported = [o for o in bpy.data.objects if o not in objects]
    if "FINISHED" not in outcome or not imported:
        raise ScriptError(f"Blender imported nothing from '{path}'")
    new_actions = [a for a in bpy.data.actions if a not in actions]
    _retime_gltf_keys(new_actions, settings["fps"], float(frame["fps"]))
    return imported


def _apply_materials(bpy: Any, imported: list[Any], settings: dict[str, Any]) -> None:
    parameters = material_parameters(settings)
    prims = [n for n in parameters if n != "World"]
    for obj in imported:
        name = part_object_prim(obj.name, prims)
        if name is None or not hasattr(obj.data, "materials"):
            continue
        obj.data.materials.clear()
        obj.data.materials.append(_material(name, parameters[name]))
        # Blender 4.2 and later import USD curves as CURVES (hair) with their widths as radii;
        # earlier ones as a CURVE, which needs a bevel to render.
        if name.startswith("Tentacles") and obj.type == "CURVE" and obj.data.splines:
            first = obj.data.splines[0].points[0].radius
            obj.data.bevel_depth = curve_bevel_depth(first, settings["tentacle_radius"])
            obj.data.bevel_resolution = 2

    scene = bpy.context.scene
    world = scene.world or bpy.data.worlds.new("jellysim water")
    scene.world = world
    world.use_nodes = True
    background = world.node_tree.nodes.get("Background")
    background.inputs["Color"].default_value = parameters["World"]["color"]
    background.inputs["Strength"].default_value = parameters["World"]["strength"]


def _add_camera_and_lights(bpy: Any, settings: dict[str, Any], aspect: float) -> None:
    """The following camera, keyed at the first and last frame and moving linearly between
    (and beyond), and the lights (:func:`light_rig`)."""
    scene = bpy.context.scene
    view = camera_placement(settings, aspect)
    camera = bpy.data.objects.new("jellysim camera", bpy.data.cameras.new("jellysim camera"))
    camera.rotation_euler = camera_rotation(view["direction"])
    camera.data.sensor_fit = "HORIZONTAL"
    camera.data.angle = view["angle"]
    camera.data.clip_start, camera.data.clip_end = view["clip_start"], view["clip_end"]
    scene.collection.objects.link(camera)
    scene.camera = camera
    camera.location = view["first"]
    if settings["last_frame"] != settings["first_frame"]:
        camera.keyframe_insert("location", frame=settings["first_frame"])
        camera.location = view["last"]
        camera.keyframe_insert("location", frame=settings["last_frame"])
        for curve in _fcurves(camera.animation_data.action):
            curve.extrapolation = "LINEAR"
            for key in curve.keyframe_points:
                key.interpolation = "LINEAR"

    for light in light_rig(settings["camera_half"], view["distance"]):
        data = bpy.data.lights.new(light["name"], light["type"])
        data.energy = light["energy"]
        if "size" in light:
            data.size = light["size"]
        obj = bpy.data.objects.new(light["name"], data)
        if "camera_offset" in light:  # rides with the camera, shining along its view
            obj.parent = camera
            obj.location = light["camera_offset"]
        else:
            obj.rotation_euler = light["rotation"]
        scene.collection.objects.link(obj)


def _set_up_render(bpy: Any, settings: dict[str, Any], options: argparse.Namespace) -> None:
    scene = bpy.context.scene
    frame = render_settings(settings, options.size)
    for key in ("frame_start", "frame_end", "frame_step"):
        setattr(scene, key, frame[key])
    for key in ("fps", "fps_base", "resolution_x", "resolution_y"):
        setattr(scene.render, key, frame[key])
    scene.render.resolution_percentage = 100
    scene.frame_set(settings["first_frame"])
    # Cycles renders on any CPU without a display or GPU (EEVEE needs an OpenGL or Vulkan
    # context), and refracts through the translucent bell.
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = options.samples
    scene.cycles.use_denoising = True
    # The look's colours as the other renderers show them: linear RGB to sRGB, no tone curve.
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "PNG"


def _find_blender_usd_module(bpy: Any) -> None:
    """Make USD's ``pxr`` importable where Blender ships it but its Python's path lacks it (the
    bpy module keeps it in its own site-packages, appended here: last, so it shadows nothing)."""
    try:
        import pxr  # noqa: F401
    except ImportError:
        version = f"python{sys.version_info.major}.{sys.version_info.minor}"
        bundled = Path(bpy.utils.resource_path("LOCAL")) / "python" / "lib" / version
        if (bundled / "site-packages" / "pxr").is_dir():
            sys.path.append(str(bundled / "site-packages"))


def _first_line(error: BaseException) -> str:
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__


def run(argv: list[str], script: Path) -> None:
    """Import the stage or glTF part and set the scene up, then save and render as asked
    (inside Blender, or a Python with the bpy module)."""
    options = parse_arguments(script_arguments(argv, script))
    try:
        import bpy
    except ImportError:
        raise ScriptError(
            f"no Blender here: run blender --background --python {SCRIPT} -- FILE, or "
            f"python {SCRIPT} FILE with the bpy module installed (pip install bpy)"
        ) from None
    if not script.is_file():  # run from Blender's text editor: the text block's file
        texts = [t.filepath for t in bpy.data.texts if t.filepath.endswith(script.name)]
        script = Path(bpy.path.abspath(texts[0])) if texts else script
    _find_blender_usd_module(bpy)
    stage = stage_path(options.stage, script)
    settings = load_settings(stage)
    render = frames_to_render(settings, options.frames) if options.render else []
    gltf = is_gltf(stage)
    if not gltf and not bpy.app.build_options.usd:
        raise ScriptError(NO_USD.format(version=bpy.app.version_string))

    _clear_start_up_scene(bpy)
    imported = _import_gltf(bpy, stage, settings) if gltf else _import_stage(bpy, stage)
    _apply_materials(bpy, imported, settings)
    width, height = options.size
    _add_camera_and_lights(bpy, settings, width / height)
    _set_up_render(bpy, settings, options)

    scene = bpy.context.scene
    if options.save is not None:
        options.save.parent.mkdir(parents=True, exist_ok=True)
        bpy.ops.wm.save_as_mainfile(filepath=str(options.save.resolve()))
        print(f"saved {options.save}", file=sys.stderr)
    for frame, path in zip(render, render_paths(options.render or Path(), render), strict=True):
        path.parent.mkdir(parents=True, exist_ok=True)
        scene.frame_set(frame)
        scene.render.filepath = str(path.resolve())
        bpy.ops.render.render(write_still=True)
        if not path.is_file():
            raise ScriptError(f"Blender rendered frame {frame} but wrote no '{path}'")
        print(f"rendered frame {frame} to {path}", file=sys.stderr)


def main(argv: list[str] | None = None) -> None:
    """Run the script; a failure is one line on stderr and exit status 2 (1 for an error of
    the script itself) when it was run from the command line, an exception Blender reports
    when run from its text editor."""
    argv = sys.argv if argv is None else argv
    script = Path(__file__)
    if not from_command_line(argv, script):
        run(argv, script)
        return
    try:
        run(argv, script)
    except (ScriptError, OSError, RuntimeError) as error:
        print(f"{SCRIPT}: error: {_first_line(error)}", file=sys.stderr)
        sys.exit(2)
    except Exception as error:  # a bug here: still one line, and a failing status
        print(
            f"{SCRIPT}: internal error: {type(error).__name__}: {_first_line(error)}",
            file=sys.stderr,
        )
        sys.exit(1)


if __name__ == "__main__":
    main()
