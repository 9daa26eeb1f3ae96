"""Import a jellysim USD stage into Blender, ready to render.

``jellysim export DIR --format usd`` writes this script as ``import_into_blender.py`` next to the
stage. Run it in a Blender with USD support (the official builds; Blender's own USD importer
does the geometry)::

    blender --python import_into_blender.py -- brown-jelly.usdc

or open it in Blender's text editor and press Run Script (it imports the stage next to it). It
imports the stage (``bpy.ops.wm.usd_import``), gives the bell a translucent glowing material and
the tentacles and fluid theirs in the scene's ``[look]`` colours (each tentacle group of a scene
of several in its own colour), colours the world as the water,
adds a camera framing the whole animation and a key and a fill light, and sets the frame range,
frame step, fps and resolution from the stage.

What it needs of the stage (colours, frame range, bounds, the renderers' camera direction and
field of view) the exporter writes into the stage's layer metadata (``customLayerData``, key
``jellysim``) and, for a Blender whose Python lacks USD's ``pxr`` module, into
``EMBEDDED_SETTINGS`` below. Everything but :func:`main` and its helpers is plain Python on plain
values; ``bpy`` and ``pxr`` are imported only inside the functions that need them, so the file
imports (and is tested) without Blender. It imports nothing of jellysim.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

METADATA_KEY = "jellysim"  # the stage layer's customLayerData key
RESOLUTION = (1920, 1080)  # pixels
CAMERA_MARGIN = 1.1  # distance beyond the one that just fits the animation's bounding sphere
EMBEDDED_SETTINGS: dict[str, Any] | None = None  # the exporter writes the stage's settings here

VECTORS = ("bounds_min", "bounds_max", "view_direction")
COLORS = ("bell_color", "bell_emissive", "tentacle_color", "water_color", "fluid_color")
NUMBERS = ("fps", "bell_transparency", "glow", "tentacle_radius", "field_of_view")
INTEGERS = ("first_frame", "last_frame", "frame_step")


def settings_from_metadata(metadata: dict[str, Any]) -> dict[str, Any]:
    """The stage's ``customLayerData['jellysim']`` as plain Python values (lists of floats for
    vectors and colours); raises ValueError naming a missing key."""
    settings: dict[str, Any] = {}
    for key in (*VECTORS, *COLORS, *NUMBERS, *INTEGERS, "stage_file"):
        if key not in metadata:
            raise ValueError(f"the stage's jellysim metadata lacks '{key}'")
    for key in (*VECTORS, *COLORS):
        settings[key] = [float(v) for v in metadata[key]]
    for key in NUMBERS:
        settings[key] = float(metadata[key])
    for key in INTEGERS:
        settings[key] = int(metadata[key])
    settings["stage_file"] = str(metadata["stage_file"])
    # A scene of several tentacle groups: each group's prim name and colour (flat, 3 a group).
    prims = [str(name) for name in metadata.get("group_prims", ())]
    colors = [float(v) for v in metadata.get("group_colors", ())]
    if len(colors) != 3 * len(prims):
        raise ValueError("the stage's jellysim metadata has group_colors unlike its group_prims")
    settings["group_colors"] = {name: colors[3 * k : 3 * k + 3] for k, name in enumerate(prims)}
    return settings


def read_stage_settings(stage_path: str | Path) -> dict[str, Any]:
    """Settings read from the stage's metadata with USD's ``pxr`` (in usd-core, and in
    Blender builds that ship USD's Python module)."""
    from pxr import Sdf

    layer = Sdf.Layer.FindOrOpen(str(stage_path))
    if layer is None:
        raise ValueError(f"cannot open the USD stage '{stage_path}'")
    metadata = dict(layer.customLayerData).get(METADATA_KEY)
    if metadata is None:
        raise ValueError(f"'{stage_path}' carries no jellysim metadata (export it again)")
    return settings_from_metadata(dict(metadata))


def load_settings(stage_path: str | Path) -> dict[str, Any]:
    """The stage's settings: from the stage where ``pxr`` imports, else the embedded copy."""
    try:
        return read_stage_settings(stage_path)
    except ImportError:
        if EMBEDDED_SETTINGS is None:
            raise
        return settings_from_metadata(EMBEDDED_SETTINGS)


def stage_path_from_arguments(argv: list[str], script: str | Path) -> Path:
    """The stage to import: the first argument after ``--``, else the stage this script was
    exported with, next to the script."""
    if "--" in argv[:-1]:
        return Path(argv[argv.index("--") + 1]).resolve()
    if EMBEDDED_SETTINGS is None:
        raise ValueError("name the stage: blender --python import_into_blender.py -- STAGE.usdc")
    return Path(script).resolve().parent / str(EMBEDDED_SETTINGS["stage_file"])


def _unit(vector: list[float]) -> list[float]:
    length = math.sqrt(sum(v * v for v in vector))
    if length == 0.0:
        raise ValueError("a zero direction")
    return [v / length for v in vector]


def camera_placement(
    low: list[float],
    high: list[float],
    direction: list[float],
    field_of_view: float,
    aspect: float,
) -> dict[str, Any]:
    """A camera looking along ``direction`` at the centre of the box ``low``..``high`` (m), far
    enough back that the box's bounding sphere fits the view: ``field_of_view`` degrees across
    the image's width, ``aspect`` = width / height. Returns location and target (m), the view
    direction (unit), clip distances (m) and the horizontal angle (radians)."""
    centre = [(a + b) / 2.0 for a, b in zip(low, high, strict=True)]
    radius = max(0.5 * math.dist(low, high), 1e-6)
    horizontal = math.radians(field_of_view)
    vertical = 2.0 * math.atan(math.tan(horizontal / 2.0) / aspect)
    half = min(horizontal, vertical) / 2.0
    distance = CAMERA_MARGIN * radius / math.sin(half)
    view = _unit(direction)
    return {
        "location": [c - distance * v for c, v in zip(centre, view, strict=True)],
        "target": centre,
        "direction": view,
        "clip_start": max(1e-4, 0.01 * (distance - radius)),
        "clip_end": 2.0 * (distance + radius),
        "angle": horizontal,
    }


def camera_rotation(direction: list[float]) -> list[float]:
    """Blender Euler XYZ angles (radians) turning a camera (which looks along its local -z, its
    up +y) to look along ``direction`` with no roll in a z-up world."""
    dx, dy, dz = _unit(direction)
    return [math.acos(max(-1.0, min(1.0, -dz))), 0.0, math.atan2(-dx, dy)]


def light_rig(low: list[float], high: list[float]) -> list[dict[str, Any]]:
    """A key light from above (a sun, as daylight through water) and a soft fill from below and
    behind the camera's side (an area light), placed about the box ``low``..``high`` (m)."""
    centre = [(a + b) / 2.0 for a, b in zip(low, high, strict=True)]
    size = max(math.dist(low, high), 1e-3)
    fill = [centre[0] - size, centre[1] - 1.5 * size, centre[2] - 0.5 * size]
    return [
        {
            "name": "jellysim key",
            "type": "SUN",
            "location": [centre[0], centre[1], centre[2] + 2.0 * size],
            "rotation": [math.radians(20.0), 0.0, math.radians(30.0)],
            "energy": 3.0,  # W/m2
        },
        {
            "name": "jellysim fill",
            "type": "AREA",
            "location": fill,
            "rotation": camera_rotation([c - f for c, f in zip(centre, fill, strict=True)]),
            "energy": 40.0 * size * size,  # W, grows with the area to light
            "size": size,
        },
    ]


def material_parameters(settings: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Principled BSDF inputs per imported prim (Bell, Tentacles, each tentacle group's prim,
    Fluid) and the world colour, from the shared materials of the scene's [look] as the other
    exports use them."""
    bell = settings["bell_color"]
    parameters = {
        "Bell": {
            "base_color": [*bell, 1.0],
            "alpha": 1.0 - settings["bell_transparency"],
            "roughness": 0.3,
            "transmission": settings["bell_transparency"],
            "emission_color": [*settings["bell_emissive"], 1.0],
            "emission_strength": 1.0,
            "blend": True,
        },
        "Tentacles": {
            "base_color": [*settings["tentacle_color"], 1.0],
            "alpha": 1.0,
            "roughness": 0.6,
            "transmission": 0.0,
            "emission_color": [0.0, 0.0, 0.0, 1.0],
            "emission_strength": 0.0,
            "blend": False,
        },
        "Fluid": {
            "base_color": [*settings["fluid_color"], 1.0],
            "alpha": 0.4,
            "roughness": 0.2,
            "transmission": 0.0,
            "emission_color": [0.0, 0.0, 0.0, 1.0],
            "emission_strength": 0.0,
            "blend": True,
        },
        "World": {"color": [*settings["water_color"], 1.0], "strength": 1.0},
    }
    for name, color in settings.get("group_colors", {}).items():
        parameters[name] = {**parameters["Tentacles"], "base_color": [*color, 1.0]}
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
    """Bevel depth (m) of an imported curve object: Blender scales the bevel by each point's
    radius, which the importer sets from the curve widths (m); where it left the default 1, the
    bevel itself carries the scene's tentacle radius."""
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
    if parameters["blend"]:
        if hasattr(material, "surface_render_method"):  # EEVEE Next (Blender 4.2 and later)
            material.surface_render_method = "BLENDED"
        else:
            material.blend_method = "BLEND"
    return material


def main(argv: list[str] | None = None) -> None:
    """Import the stage and set the scene up (inside Blender)."""
    try:
        import bpy
    except ImportError:
        raise SystemExit(
            "run this script in Blender: blender --python import_into_blender.py -- STAGE.usdc"
        ) from None

    script = Path(__file__)
    if not script.is_file():  # run from Blender's text editor: the text block's file
        texts = [t.filepath for t in bpy.data.texts if t.filepath.endswith(script.name)]
        script = Path(bpy.path.abspath(texts[0])) if texts else script
    stage = stage_path_from_arguments(sys.argv if argv is None else argv, script)
    settings = load_settings(stage)
    scene = bpy.context.scene
    before = set(bpy.data.objects)
    bpy.ops.wm.usd_import(filepath=str(stage), set_frame_range=True)
    imported = [o for o in bpy.data.objects if o not in before]

    parameters = material_parameters(settings)
    # Longest first: a group's prim "Tentacles_arms" before "Tentacles".
    prims = sorted((n for n in parameters if n != "World"), key=len, reverse=True)
    for obj in imported:
        name = next((n for n in prims if obj.name.startswith(n)), None)
        if name is None or not hasattr(obj.data, "materials"):
            continue
        obj.data.materials.clear()
        obj.data.materials.append(_material(name, parameters[name]))
        if name.startswith("Tentacles") and obj.type == "CURVE" and obj.data.splines:
            first = obj.data.splines[0].points[0].radius
            obj.data.bevel_depth = curve_bevel_depth(first, settings["tentacle_radius"])
            obj.data.bevel_resolution = 2

    world = scene.world or bpy.data.worlds.new("jellysim water")
    scene.world = world
    world.use_nodes = True
    background = world.node_tree.nodes.get("Background")
    background.inputs["Color"].default_value = parameters["World"]["color"]
    background.inputs["Strength"].default_value = parameters["World"]["strength"]

    frame = render_settings(settings)
    for key in ("frame_start", "frame_end", "frame_step"):
        setattr(scene, key, frame[key])
    for key in ("fps", "fps_base", "resolution_x", "resolution_y"):
        setattr(scene.render, key, frame[key])
    scene.render.resolution_percentage = 100

    view = camera_placement(
        settings["bounds_min"],
        settings["bounds_max"],
        settings["view_direction"],
        settings["field_of_view"],
        frame["resolution_x"] / frame["resolution_y"],
    )
    camera = bpy.data.objects.new("jellysim camera", bpy.data.cameras.new("jellysim camera"))
    camera.location = view["location"]
    camera.rotation_euler = camera_rotation(view["direction"])
    camera.data.sensor_fit = "HORIZONTAL"
    camera.data.angle = view["angle"]
    camera.data.clip_start, camera.data.clip_end = view["clip_start"], view["clip_end"]
    scene.collection.objects.link(camera)
    scene.camera = camera

    for light in light_rig(settings["bounds_min"], settings["bounds_max"]):
        data = bpy.data.lights.new(light["name"], light["type"])
        data.energy = light["energy"]
        if "size" in light:
            data.size = light["size"]
        obj = bpy.data.objects.new(light["name"], data)
        obj.location = light["location"]
        obj.rotation_euler = light["rotation"]
        scene.collection.objects.link(obj)


if __name__ == "__main__":
    main()
