"""The exported ``import_into_blender.py`` run for real in Blender as a Python module (bpy 5.0.1
from PyPI, in its own venv ``.venv-blender`` that ``make blender`` makes, so that its numpy pin
stays out of jellysim's): it clears the start-up scene, imports the USD stage or the glTF part,
follows the jellyfish with the camera of ``jellysim render --camera follow``, renders small frames
in Cycles on the CPU and saves a .blend, read back here (for glTF: the result's frame range and
fps, and every frame's geometry, evaluated by Blender, the result's); and every failure is one
line and exit status 2.

bpy 5.0.1 is built for CPython 3.11 only: the test skips only where no Python 3.11 is there to
install it for."""

from __future__ import annotations

import colorsys
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import jellysim
from jellysim import fields
from jellysim.export import export
from jellysim.export.groups import export_groups
from jellysim.render.materials import Material, bell_material, group_look, group_material
from jellysim.render.pipeline import VIEW_DIRECTION, frame_cameras, make_members, scene_look

pxr = pytest.importorskip("pxr", reason="usd-core is a test dependency (pip install -e .[test])")
from pxr import Usd  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
BPY_PYTHON = Path(os.environ.get("JELLYSIM_BPY_PYTHON", ROOT / ".venv-blender" / "bin" / "python"))
SIZE = (160, 120)
TIMEOUT = 240  # s for one Blender run (a few seconds each here)

# The inputs of each object's Principled BSDF in a .blend opened in the bpy venv: "shading"
# maps an object's name to its first material's inputs and render method.
READ_SHADING = """
def shading(objects):
    inputs = ("Base Color", "Alpha", "Transmission Weight", "Roughness", "Emission Color",
              "Emission Strength", "IOR")
    found = {}
    for obj in objects:
        if not getattr(obj.data, "materials", None):
            continue
        material = obj.data.materials[0]
        shader = material.node_tree.nodes["Principled BSDF"]
        values = {n: shader.inputs[n].default_value for n in inputs}
        found[obj.name] = {n: v if isinstance(v, float) else list(v) for n, v in values.items()}
        found[obj.name]["method"] = material.surface_render_method
    return found
"""

# Reads a saved .blend back, in the bpy venv: the scene's objects, frames, fps, render settings,
# each object's material inputs and the camera's world location and view direction at every
# frame.
READ_BLEND = (
    READ_SHADING
    + """
import json, sys
import bpy
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
scene = bpy.context.scene
camera = scene.camera
facts = {
    "objects": sorted(o.name for o in scene.objects),
    "frames": [scene.frame_start, scene.frame_end, scene.frame_step],
    "fps": scene.render.fps / scene.render.fps_base,
    "engine": scene.render.engine,
    "resolution": [scene.render.resolution_x, scene.render.resolution_y],
    "angle": camera.data.angle,
    "sensor_fit": camera.data.sensor_fit,
    "camera": {},
    "materials": {o.name: [m.name for m in o.data.materials]
                  for o in scene.objects if hasattr(o.data, "materials")},
    "shading": shading(scene.objects),
}
for frame in range(scene.frame_start, scene.frame_end + 1):
    scene.frame_set(frame)
    matrix = camera.matrix_world
    facts["camera"][frame] = {
        "location": list(matrix.translation),
        "forward": list(matrix.to_3x3().col[2] * -1.0),
    }
print("FACTS " + json.dumps(facts))
"""
)


def _bpy_python() -> Path:
    if BPY_PYTHON.is_file():
        return BPY_PYTHON
    if sys.version_info[:2] == (3, 11) or shutil.which("python3.11"):
        pytest.fail(f"no {BPY_PYTHON}: run 'make blender' (bpy for Python 3.11, in its own venv)")
    pytest.skip("bpy 5.0.1 (Blender as a Python module) is built for CPython 3.11, not found here")


def _blender(
    *args: str | Path, python: Path | None = None, **env: str
) -> subprocess.CompletedProcess:
    command = [str(python or _bpy_python()), *map(str, args)]
    # The script imports nothing of this checkout: no PYTHONPATH but the one given.
    environment = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | env
    return subprocess.run(
        command, capture_output=True, text=True, timeout=TIMEOUT, env=environment, check=False
    )


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory):
    """brown-jelly (bell, marginal tentacles and oral arms), 5 frames, exported to USD."""
    folder = tmp_path_factory.mktemp("blender-import")
    overrides = {"duration": 0.4, "fps": 10.0, "tentacles.particles": 20}
    result = jellysim.run(jellysim.load_scene("brown-jelly", overrides), folder / "run")
    stage, script = export(result, "usd", folder / "usd")
    return result, stage, script, folder


@pytest.fixture(scope="module")
def rendered(exported):
    """The script run as ``python import_into_blender.py STAGE ...``: frames 1 and 2 rendered
    and the scene saved; then the .blend read back."""
    result, stage, script, folder = exported
    _bpy_python()
    out = folder / "render" / "jelly.png"
    blend = folder / "render" / "jelly.blend"
    size = f"{SIZE[0]}x{SIZE[1]}"
    run = _blender(
        script, stage, "--render", out, "--frames", "1:3", "--size", size, "--samples", "8",
        "--save", blend,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    read = _blender("-c", READ_BLEND, blend)
    assert read.returncode == 0, read.stderr
    line = next(t for t in read.stdout.splitlines() if t.startswith("FACTS "))
    return json.loads(line.removeprefix("FACTS ")), out, blend


def _pixels(path: Path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as image:
        return np.asarray(image.convert("RGB"), dtype=np.float64) / 255.0


def _srgb(linear: list[float] | tuple[float, ...]) -> np.ndarray:
    c = np.asarray(linear, dtype=np.float64)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def _expected_materials(result: jellysim.Result) -> dict[str, Material]:
    """Each object's material as materials.py resolves it, by prim name: the bell's and each
    tentacle group's."""
    look = scene_look(result.scene)
    expected = {"Bell": bell_material(look)}
    for group in result.scene.groups:
        name = f"tentacles_{group.name}"
        drawn = group_look(look, group.tentacles, name)
        expected[f"Tentacles_{group.name.replace('-', '_')}"] = group_material(look, drawn, name)
    return expected


def _assert_shading_is_the_look(shading: dict, result: jellysim.Result, names: dict) -> None:
    """Each object's Principled BSDF inputs (``shading``, read back from the .blend) against
    its material from materials.py (``names``: object name to prim name): base colour, opacity
    as alpha and the rest as transmission, roughness, emission colour at strength 1, ior, and
    blending for a translucent material."""
    expected = _expected_materials(result)
    assert set(names.values()) == set(expected)
    for obj, prim in names.items():
        inputs, material = shading[obj], expected[prim]
        np.testing.assert_allclose(inputs["Base Color"], [*material.base_color, 1.0], atol=1e-6)
        assert inputs["Alpha"] == pytest.approx(material.opacity, abs=1e-6), obj
        assert inputs["Transmission Weight"] == pytest.approx(1.0 - material.opacity, abs=1e-6)
        assert inputs["Roughness"] == pytest.approx(material.roughness, abs=1e-6), obj
        emitted = inputs["Emission Strength"] * np.asarray(inputs["Emission Color"][:3])
        np.testing.assert_allclose(emitted, material.emissive, atol=1e-6)
        assert inputs["IOR"] == pytest.approx(material.ior, abs=1e-6), obj
        assert inputs["method"] == ("BLENDED" if material.opacity < 1.0 else "DITHERED"), obj
    # brown-jelly's oral arms: translucent glowing tissue, unlike the opaque threads.
    arms, threads = (
        shading[_key(names, "Tentacles_oral_arms")],
        shading[_key(names, "Tentacles_marginal")],
    )
    assert arms["Alpha"] < 1.0 and threads["Alpha"] == 1.0
    assert max(arms["Emission Color"][:3]) > 0.0 and max(threads["Emission Color"][:3]) == 0.0
    assert arms["Roughness"] < threads["Roughness"]


def _key(names: dict, prim: str) -> str:
    return next(obj for obj, p in names.items() if p == prim)


def test_the_start_up_scene_is_replaced_by_the_stage(rendered) -> None:
    facts, _, blend = rendered
    assert blend.is_file()
    assert facts["objects"] == [
        "Bell",
        "Jellyfish",
        "Tentacles_marginal",
        "Tentacles_oral_arms",
        "jellysim camera",
        "jellysim fill",
        "jellysim key",
    ]  # no start-up cube, light or camera
    assert facts["materials"]["Bell"] == ["jellysim Bell"]
    assert facts["materials"]["Tentacles_oral_arms"] == ["jellysim Tentacles_oral_arms"]
    assert facts["engine"] == "CYCLES" and facts["resolution"] == list(SIZE)


def test_each_object_s_material_is_the_look_s(exported, rendered) -> None:
    """One look in Blender too: the saved .blend's materials are materials.py's (the oral arms'
    translucent, glowing tissue included)."""
    result, _, _, _ = exported
    facts, _, _ = rendered
    names = {p: p for p in ("Bell", "Tentacles_marginal", "Tentacles_oral_arms")}
    _assert_shading_is_the_look(facts["shading"], result, names)


def test_frame_range_and_fps_are_the_stage_s(exported, rendered) -> None:
    _, stage_path, _, _ = exported
    facts, _, _ = rendered
    stage = Usd.Stage.Open(str(stage_path))
    assert facts["frames"] == [stage.GetStartTimeCode(), stage.GetEndTimeCode(), 1]
    assert facts["fps"] == pytest.approx(stage.GetFramesPerSecond())
    assert stage.GetFramesPerSecond() == 10.0


def test_the_camera_follows_as_jellysim_render_does(exported, rendered) -> None:
    result, _, _, _ = exported
    facts, _, _ = rendered
    members = make_members([result], 1, None, 0, fluid=False)
    cameras, _, mode = frame_cameras(members, result.frames, SIZE, "follow")
    assert mode == "follow"
    view = VIEW_DIRECTION / np.linalg.norm(VIEW_DIRECTION)
    assert facts["sensor_fit"] == "HORIZONTAL"
    assert facts["angle"] == pytest.approx(np.radians(cameras[0].angle))
    for frame, camera in enumerate(cameras):
        seen = facts["camera"][str(frame)]
        np.testing.assert_allclose(seen["location"], camera.location, atol=2e-6)
        np.testing.assert_allclose(seen["forward"], view, atol=1e-6)
    travel = np.subtract(facts["camera"]["4"]["location"], facts["camera"]["0"]["location"])
    assert np.linalg.norm(travel) > 0.01  # it moves with the swimmer (metres in 4 frames)


def test_rendered_frames_show_the_jellyfish_framed_and_lit(exported, rendered) -> None:
    result, _, _, _ = exported
    _, out, _ = rendered
    look = scene_look(result.scene)
    frames = [out.with_name("jelly_00001.png"), out.with_name("jelly_00002.png")]
    assert not out.exists() and all(f.is_file() for f in frames)
    images = [_pixels(f) for f in frames]
    for image in images:
        assert image.shape == (SIZE[1], SIZE[0], 3)
        assert image.std() > 0.08  # not a flat picture
        # The background is the water: its colour in the top corners (linear RGB to sRGB).
        for corner in (image[:6, :6], image[:6, -6:]):
            np.testing.assert_allclose(corner.mean(axis=(0, 1)), _srgb(look.water_color), atol=0.06)
        # The jellyfish: warm pixels of the bell's and tentacles' hue, large in the middle.
        warm = image[..., 0] > image[..., 2] + 0.15
        assert warm.mean() > 0.08  # the bell alone covers about a tenth of the picture
        hues = np.array([colorsys.rgb_to_hsv(*p)[0] for p in image[warm]])
        bell_hue = colorsys.rgb_to_hsv(*look.bell_color)[0]
        assert abs(float(np.median(hues)) - bell_hue) < 0.06  # within about 20 degrees
        rows, columns = np.nonzero(warm)
        assert rows.max() - rows.min() > 0.5 * SIZE[1]  # framed: half the height, not a sixth
        assert abs(columns.mean() - SIZE[0] / 2) < 0.1 * SIZE[0]  # and in the middle
        brightest = np.median(image[warm].max(axis=1))
        assert 0.3 < brightest < 0.98  # lit, neither dark nor washed out to white
    assert np.abs(images[0] - images[1]).max() > 0.05  # the bell pulses between frames


def test_blender_s_argument_style_renders_one_frame(exported, tmp_path: Path) -> None:
    _, stage, script, _ = exported
    out = tmp_path / "one.png"
    run = _blender(script, "--", stage, "--render", out, "--size", "64x48", "--samples", "2")
    assert run.returncode == 0, run.stderr
    image = _pixels(out)
    assert image.shape == (48, 64, 3) and image.std() > 0.05
    assert "rendered frame 0" in run.stderr


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["missing.usdc"], "no USD stage at"),
        (["STAGE", "--size", "10"], "--size: '10': expected WxH"),
        (["STAGE", "--render", "out.jpg"], "expected a path ending in .png"),
        (["STAGE", "--render", "out.png", "--frames", "7:9"], "the file has frames 0 to 4"),
        (["STAGE", "--save", "x.txt"], "expected a path ending in .blend"),
        (["STAGE", "--colour", "red"], "unrecognized arguments: --colour red"),
        (["GARBAGE"], "File too small"),
    ],
)
def test_failures_are_one_line_and_status_2(exported, tmp_path: Path, arguments, message) -> None:
    _, stage, script, _ = exported
    garbage = tmp_path / "garbage.usdc"
    garbage.write_text("not a stage\n", encoding="utf-8")
    names = {"STAGE": str(stage), "GARBAGE": str(garbage)}
    run = _blender(script, *(names.get(a, a) for a in arguments))
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2
    assert len(lines) == 1 and lines[0].startswith("import_into_blender.py: error: "), lines
    assert message in lines[0]


def test_a_blender_without_usd_is_told_which_builds_read_it(exported, tmp_path: Path) -> None:
    """Debian's blender (3.4, no USD) is a system package CI does not install: a stand-in
    ``bpy`` with its build options, under this Python (usd-core reads the stage's settings)."""
    _, stage, script, _ = exported
    standin = tmp_path / "bpy.py"
    standin.write_text(
        "from types import SimpleNamespace\n"
        "app = SimpleNamespace(version_string='3.4.1', build_options=SimpleNamespace(usd=False))\n",
        encoding="utf-8",
    )
    run = _blender(script, stage, python=Path(sys.executable), PYTHONPATH=str(tmp_path))
    assert run.returncode == 2
    assert run.stderr.strip() == (
        "import_into_blender.py: error: Blender 3.4.1 was built without USD support (as Debian's "
        "and Ubuntu's blender packages are): use an official build from blender.org, or the bpy "
        "module (pip install bpy)"
    )


# The glTF route: a part of a result at a frame rate Blender stores as fps / fps_base (12.5 =
# 12 / 0.96), which its glTF importer misreads (it keys time x fps x fps_base).

# Reads a saved .blend back, in the bpy venv: frames, fps, objects, materials and their inputs,
# shape keys, the
# keyframes' frames, the camera's location, and every mesh's evaluated world vertices at every
# frame of the range (argv[2], a .npz).
READ_GLTF_BLEND = (
    READ_SHADING
    + """
import json, sys
import bpy
import numpy as np
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
scene = bpy.context.scene
meshes = [o for o in scene.objects if o.type == "MESH"]
facts = {
    "objects": sorted(o.name for o in scene.objects),
    "frames": [scene.frame_start, scene.frame_end, scene.frame_step],
    "fps": scene.render.fps / scene.render.fps_base,
    "materials": {o.name: [m.name for m in o.data.materials] for o in meshes},
    "shape_keys": {o.name: len(o.data.shape_keys.key_blocks) for o in meshes},
    "shading": shading(meshes),
    "keys": sorted({k.co[0] for a in bpy.data.actions for layer in a.layers
                    for strip in layer.strips for bag in strip.channelbags
                    for curve in bag.fcurves for k in curve.keyframe_points}),
    "camera": {},
}
positions = {}
for frame in range(scene.frame_start, scene.frame_end + 1):
    scene.frame_set(frame)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    facts["camera"][frame] = list(scene.camera.matrix_world.translation)
    for obj in meshes:
        evaluated = obj.evaluated_get(depsgraph)
        mesh = evaluated.to_mesh()
        co = np.empty(3 * len(mesh.vertices))
        mesh.vertices.foreach_get("co", co)
        world = np.asarray(evaluated.matrix_world)
        positions[f"{obj.name}/{frame}"] = co.reshape(-1, 3) @ world[:3, :3].T + world[:3, 3]
        evaluated.to_mesh_clear()
np.savez(sys.argv[2], **positions)
print("FACTS " + json.dumps(facts))
"""
)


@pytest.fixture(scope="module")
def gltf_exported(tmp_path_factory: pytest.TempPathFactory):
    """brown-jelly, 6 frames at 12.5 fps, exported to glTF (a part, the index, the script)."""
    folder = tmp_path_factory.mktemp("blender-gltf")
    overrides = {"duration": 0.4, "fps": 12.5, "tentacles.particles": 20}
    result = jellysim.run(jellysim.load_scene("brown-jelly", overrides), folder / "run")
    part, _, script = export(result, "gltf", folder / "gltf")
    return result, part, script, folder


@pytest.fixture(scope="module")
def gltf_rendered(gltf_exported):
    """The exported script run as ``python import_into_blender.py PART --render ... --frames
    2:3 --save ...``; the .blend read back: its facts and every mesh's vertices at every
    frame."""
    result, part, script, folder = gltf_exported
    _bpy_python()
    out, blend = folder / "render" / "jelly.png", folder / "render" / "jelly.blend"
    size = f"{SIZE[0]}x{SIZE[1]}"
    run = _blender(
        script, part, "--render", out, "--frames", "2:3", "--size", size, "--samples", "8",
        "--save", blend,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert "rendered frame 2" in run.stderr
    positions = folder / "positions.npz"
    read = _blender("-c", READ_GLTF_BLEND, blend, positions)
    assert read.returncode == 0, read.stderr
    line = next(t for t in read.stdout.splitlines() if t.startswith("FACTS "))
    return result, json.loads(line.removeprefix("FACTS ")), dict(np.load(positions)), out


def test_gltf_the_start_up_scene_is_replaced_by_the_part(gltf_rendered) -> None:
    result, facts, _, _ = gltf_rendered
    assert facts["objects"] == [
        "bell",
        "brown-jelly",  # the glTF root node
        "jellysim camera",
        "jellysim fill",
        "jellysim key",
        "tentacles_marginal",
        "tentacles_oral_arms",
    ]  # no start-up cube, light or camera; one object per part of the jellyfish
    assert facts["materials"] == {
        "bell": ["jellysim Bell"],
        "tentacles_marginal": ["jellysim Tentacles_marginal"],
        "tentacles_oral_arms": ["jellysim Tentacles_oral_arms"],
    }
    # A shape key per frame: the basis (frame 0) and one per later frame.
    assert set(facts["shape_keys"].values()) == {result.frames}


def test_gltf_each_object_s_material_is_the_look_s(gltf_rendered) -> None:
    result, facts, _, _ = gltf_rendered
    names = {
        "bell": "Bell",
        "tentacles_marginal": "Tentacles_marginal",
        "tentacles_oral_arms": "Tentacles_oral_arms",
    }
    _assert_shading_is_the_look(facts["shading"], result, names)


def test_gltf_frame_range_fps_and_keys_are_the_result_s(gltf_rendered) -> None:
    result, facts, _, _ = gltf_rendered
    assert result.frames == 6 and float(result.file.attrs["fps"]) == 12.5
    assert facts["frames"] == [0, result.frames - 1, 1]
    assert facts["fps"] == pytest.approx(12.5, rel=1e-6)
    # Keyframes on the frame numbers exactly (and the last frame's hold one frame on).
    assert facts["keys"] == [float(f) for f in range(result.frames + 1)]


def test_gltf_every_frame_shows_that_frame_s_geometry(gltf_rendered) -> None:
    """Blender's evaluated meshes at each frame against result.h5: the bell's vertices, and the
    tip of every drawn marginal tentacle at the centre of its tube's tip cap (float32)."""
    result, _, positions, _ = gltf_rendered
    (marginal, _) = export_groups(result, scene_look(result.scene), None)
    for frame in range(result.frames):
        bell = result.read(fields.BELL_SURFACE_VERTICES, frame)
        np.testing.assert_allclose(positions[f"bell/{frame}"], bell, atol=1e-6)
        if frame:  # the bell moves between frames: a frame off would show
            earlier = result.read(fields.BELL_SURFACE_VERTICES, frame - 1)
            assert np.abs(bell - earlier).max() > 1e-3
        tips = marginal.positions[frame][:, -1]  # (drawn tentacles, 3) m
        tube = positions[f"tentacles_marginal/{frame}"]
        nearest = np.linalg.norm(tube[None] - tips[:, None], axis=-1).min(axis=1)
        assert nearest.max() < 1e-6


def test_gltf_camera_follows_as_for_usd(gltf_rendered) -> None:
    result, facts, _, _ = gltf_rendered
    members = make_members([result], 1, None, 0, fluid=False)
    cameras, _, _ = frame_cameras(members, result.frames, SIZE, "follow")
    for frame, camera in enumerate(cameras):
        np.testing.assert_allclose(facts["camera"][str(frame)], camera.location, atol=2e-6)


def test_gltf_rendered_frame_shows_the_jellyfish(gltf_rendered) -> None:
    result, _, _, out = gltf_rendered
    look = scene_look(result.scene)
    image = _pixels(out)
    assert image.shape == (SIZE[1], SIZE[0], 3)
    assert image.std() > 0.08  # not a flat picture
    for corner in (image[:6, :6], image[:6, -6:]):
        np.testing.assert_allclose(corner.mean(axis=(0, 1)), _srgb(look.water_color), atol=0.06)
    warm = image[..., 0] > image[..., 2] + 0.15
    assert warm.mean() > 0.08  # the bell's hue over about a tenth of the picture
    rows, columns = np.nonzero(warm)
    assert rows.max() - rows.min() > 0.5 * SIZE[1]
    assert abs(columns.mean() - SIZE[0] / 2) < 0.1 * SIZE[0]


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("missing.glb", None, "no glTF file at"),
        ("plain.gltf", '{"asset": {"version": "2.0"}, "scenes": [{}]}', "no jellysim settings"),
        ("garbage.glb", "not glTF", "is not a glTF file"),
    ],
)
def test_gltf_failures_are_one_line_and_status_2(
    gltf_exported, tmp_path: Path, name, content, message
) -> None:
    _, _, script, _ = gltf_exported
    path = tmp_path / name
    if content is not None:
        path.write_text(content, encoding="utf-8")
    run = _blender(script, path, "--render", tmp_path / "x.png")
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2
    assert len(lines) == 1 and lines[0].startswith("import_into_blender.py: error: "), lines
    assert message in lines[0]
