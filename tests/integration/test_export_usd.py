"""``jellysim export --format usd``: one stage read back with usd-core, compared with result.h5
at several time codes, and passing USD's own validators (UsdValidation, all registered); and the
Blender script written beside it, its logic run here without Blender on the stage's metadata."""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

import numpy as np
import pytest

import jellysim
from jellysim import fields
from jellysim.export import export
from jellysim.interpolation import interpolate_result
from jellysim.render.materials import bell_material, fluid_material, tentacle_material
from jellysim.render.pipeline import (
    FIELD_OF_VIEW,
    VIEW_DIRECTION,
    frame_cameras,
    make_members,
    scene_look,
)

pxr = pytest.importorskip("pxr", reason="usd-core is a test dependency (pip install -e .[test])")
from pxr import Usd, UsdGeom, UsdShade, UsdValidation  # noqa: E402


@pytest.fixture(scope="module")
def stage_and_result(tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.mktemp("brown")
    # brown-jelly's marginal tentacles alone (the oral arms are a second group: the exports of
    # groups are tests/integration/test_export_groups.py's), 60 particles a tentacle: the counts
    # below assume them (the preset has 90 since issue 25).
    overrides = {"duration": 0.4, "fps": 10.0, "tentacles.particles": 60}
    scene = jellysim.load_scene("brown-jelly", overrides).group_scene(0)
    result = jellysim.run(scene, folder)
    path, _ = export(result, "usd", folder / "usd", interpolation=2)
    return Usd.Stage.Open(str(path)), result


def test_stage_metadata(stage_and_result) -> None:
    stage, result = stage_and_result
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert stage.GetDefaultPrim().GetPath() == "/Jellyfish"
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, result.frames - 1)
    assert stage.GetTimeCodesPerSecond() == 10.0
    assert stage.GetFramesPerSecond() == 10.0  # authored: importers do not fall back to 24
    assert stage.GetRootLayer().HasFramesPerSecond()


@pytest.mark.parametrize(
    ("prim", "material"),
    [("Bell", bell_material), ("Tentacles", tentacle_material)],
)
def test_prims_are_bound_to_preview_surfaces_of_the_look(stage_and_result, prim, material) -> None:
    stage, result = stage_and_result
    expected = material(scene_look(result.scene))
    geometry = stage.GetPrimAtPath(f"/Jellyfish/{prim}")
    bound, _ = UsdShade.MaterialBindingAPI(geometry).ComputeBoundMaterial()
    assert bound.GetPath() == f"/Jellyfish/Looks/{prim}"
    source = bound.ComputeSurfaceSource()[0]
    assert source.GetIdAttr().Get() == "UsdPreviewSurface"
    inputs = {i.GetBaseName(): i.Get() for i in source.GetInputs()}
    np.testing.assert_allclose(inputs["diffuseColor"], expected.base_color, atol=1e-6)
    np.testing.assert_allclose(inputs["emissiveColor"], expected.emissive, atol=1e-6)
    assert inputs["opacity"] == pytest.approx(expected.opacity)
    gprim = UsdGeom.Gprim(geometry)
    np.testing.assert_allclose(gprim.GetDisplayColorAttr().Get()[0], expected.base_color, atol=1e-6)
    assert gprim.GetDisplayOpacityAttr().Get()[0] == pytest.approx(expected.opacity)
    if prim == "Bell":  # translucent and glowing, from bell_transparency and glow
        assert 0.0 < inputs["opacity"] < 1.0
        assert max(inputs["emissiveColor"]) > 0.0


def test_bell_and_tentacles_match_the_result(stage_and_result) -> None:
    stage, result = stage_and_result
    bell = UsdGeom.Mesh(stage.GetPrimAtPath("/Jellyfish/Bell"))
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Jellyfish/Tentacles"))
    faces = result.file[fields.BELL_SURFACE_FACES.path][:]
    np.testing.assert_array_equal(np.array(bell.GetFaceVertexIndicesAttr().Get()), faces.ravel())
    drawn = interpolate_result(result, 2)
    assert list(curves.GetCurveVertexCountsAttr().Get()) == [60] * 12
    widths = np.array(curves.GetWidthsAttr().Get()).reshape(12, 60)
    assert np.all(np.diff(widths, axis=1) < 0)  # tapered from root to tip
    for frame in (0, 2, result.frames - 1):
        points = np.array(bell.GetPointsAttr().Get(frame))
        np.testing.assert_allclose(
            points, result.file[fields.BELL_SURFACE_VERTICES.path][frame], atol=1e-6
        )
        low, high = np.array(bell.GetExtentAttr().Get(frame))
        np.testing.assert_allclose(low, points.min(axis=0))
        np.testing.assert_allclose(high, points.max(axis=0))
        strands = np.array(curves.GetPointsAttr().Get(frame)).reshape(12, 60, 3)
        np.testing.assert_allclose(strands, drawn[frame], atol=1e-6)
        low, high = np.array(curves.GetExtentAttr().Get(frame))
        assert np.all(low <= strands.reshape(-1, 3).min(axis=0))
        assert np.all(high >= strands.reshape(-1, 3).max(axis=0))


def test_the_stage_passes_usd_validation(stage_and_result) -> None:
    stage, _ = stage_and_result
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    assert len(validators) > 10
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    assert [e.GetMessage() for e in errors] == []


def test_missing_usd_core_is_a_clear_input_error(monkeypatch, tmp_path: Path) -> None:
    import builtins

    real_import = builtins.__import__

    def no_pxr(name, *args, **kwargs):
        if name == "pxr" or name.startswith("pxr."):
            raise ImportError("no pxr")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_pxr)
    result = jellysim.run("brown-jelly", tmp_path, overrides={"duration": 0.1})
    with pytest.raises(jellysim.InputError, match="pip install"):
        export(result, "usd", tmp_path / "usd")


def test_fluid_particles_are_time_sampled_points(tmp_path: Path) -> None:
    import h5py

    folder = tmp_path / "fluid"
    folder.mkdir()
    rng = np.random.default_rng(5)
    alive = np.ones((2, 20), dtype=bool)
    alive[1, :3] = False
    position = rng.uniform(0, 1, (2, 20, 2))
    with h5py.File(folder / "result.h5", "w") as f:
        f[fields.TIME.path] = np.array([0.0, 0.1])
        f[fields.FLUID_POSITION.path] = position
        f[fields.FLUID_ALIVE.path] = alive
        f[fields.FLUID_KIND.path] = np.zeros(20, dtype=np.int8)
        f.attrs["scene"] = 'name = "b"\n'
        f.attrs["fps"] = 10.0
        f.attrs["frames_expected"] = 2
        f.attrs["particle_spacing"] = 0.01
    with jellysim.open_result(folder) as result:
        path, script = export(result, "usd", tmp_path / "usd")
    assert script.name == "import_into_blender.py"
    stage = Usd.Stage.Open(str(path))
    points = UsdGeom.Points(stage.GetPrimAtPath("/Jellyfish/Fluid"))
    last = np.array(points.GetPointsAttr().Get(1))
    assert last.shape == (17, 3)  # dead particles left out
    np.testing.assert_allclose(last[:, [0, 2]], position[1, 3:], atol=1e-6)  # 2-D: (x, 0, y)
    assert np.all(last[:, 1] == 0.0)
    assert list(points.GetWidthsAttr().Get()) == [pytest.approx(0.01)]


# The Blender script: its logic on the exported stage, without Blender.


def _load_script(path: Path):
    spec = importlib.util.spec_from_file_location("import_into_blender", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def blender_export(tmp_path_factory: pytest.TempPathFactory, stage_and_result):
    _, result = stage_and_result
    out = tmp_path_factory.mktemp("blender")
    stage_path, script_path = export(result, "usd", out, frames=(1, 5), every=2, interpolation=2)
    return stage_path, script_path, _load_script(script_path), result


def test_the_script_is_python_that_imports_bpy_only_inside_functions(blender_export) -> None:
    _, script_path, _, _ = blender_export
    text = script_path.read_text(encoding="utf-8")
    compile(text, str(script_path), "exec")  # valid Python
    tree = ast.parse(text)
    top_level = set()
    for node in tree.body:
        if isinstance(node, ast.Import):
            top_level |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            top_level.add(str(node.module).split(".")[0])
    standard = {"__future__", "argparse", "json", "math", "struct", "sys", "pathlib", "typing"}
    assert top_level <= standard  # no bpy
    inside = {
        function.name
        for function in ast.walk(tree)
        if isinstance(function, ast.FunctionDef)
        for node in ast.walk(function)
        if isinstance(node, ast.Import) and any(a.name == "bpy" for a in node.names)
    }
    assert inside == {"run", "_material"}
    with pytest.raises(ImportError):
        import bpy  # noqa: F401  (this test environment has no Blender)
    script = _load_script(script_path)
    with pytest.raises(script.ScriptError, match="no Blender here"):
        script.main(["blender", "--", "x.usdc"])  # from the text editor: an exception


def test_the_script_reads_the_stage_metadata(blender_export) -> None:
    stage_path, script_path, script, result = blender_export
    settings = script.read_stage_settings(stage_path)
    assert settings == script.settings_from_metadata(script.EMBEDDED_SETTINGS)  # the same copy
    assert script.load_settings(stage_path) == settings
    look = scene_look(result.scene)
    assert set(settings["materials"]) == {"Bell", "Tentacles", "Fluid"}
    for name, material in (
        ("Bell", bell_material(look)),
        ("Tentacles", tentacle_material(look)),
        ("Fluid", fluid_material()),
    ):
        stored = settings["materials"][name]
        np.testing.assert_allclose(stored["base_color"], material.base_color)
        np.testing.assert_allclose(stored["emissive"], material.emissive)
        for key in ("opacity", "roughness", "ior"):
            assert stored[key] == pytest.approx(getattr(material, key)), (name, key)
    np.testing.assert_allclose(settings["water_color"], look.water_color)
    assert settings["tentacle_radius"] == pytest.approx(look.tentacle_radius)
    assert (settings["first_frame"], settings["last_frame"], settings["frame_step"]) == (1, 3, 2)
    assert settings["fps"] == 10.0 and settings["stage_file"] == stage_path.name
    assert script.stage_path(None, script_path) == stage_path.resolve()
    assert script.stage_path(stage_path, "/elsewhere/s.py") == stage_path.resolve()
    name = script_path.name
    assert script.script_arguments(["blender", "--python", name], script_path) == []
    assert script.script_arguments(["b", "-P", name, "--", "y.usdc"], script_path) == ["y.usdc"]
    assert script.script_arguments([f"/d/{name}", "y.usdc", "--save", "a.blend"], name) == [
        "y.usdc",
        "--save",
        "a.blend",
    ]
    assert script.from_command_line(["blender", "--python", f"/d/{name}", "--", "x"], name)
    assert not script.from_command_line(["blender", "scene.blend"], name)  # the text editor
    assert script.frames_to_render(settings, None) == [1]
    assert script.frames_to_render(settings, (0, 9)) == [1, 3]  # the exported frames only
    out = Path("/r/jelly.png")
    assert script.render_paths(out, [1]) == [out]
    assert script.render_paths(out, [1, 3]) == [
        Path("/r/jelly_00001.png"),
        Path("/r/jelly_00003.png"),
    ]

    # The bounds hold the bell and every tentacle (with its radius) at every exported frame.
    stage = Usd.Stage.Open(str(stage_path))
    low, high = np.array(settings["bounds_min"]), np.array(settings["bounds_max"])
    drawn = interpolate_result(result, 2)
    for frame in (1, 3):
        bell = result.file[fields.BELL_SURFACE_VERTICES.path][frame]
        for points in (bell, drawn[frame].reshape(-1, 3)):
            assert np.all(points >= low - 1e-6) and np.all(points <= high + 1e-6)
        for prim in ("Bell", "Tentacles"):
            box = np.array(
                UsdGeom.Boundable(stage.GetPrimAtPath(f"/Jellyfish/{prim}"))
                .GetExtentAttr()
                .Get(frame)
            )
            assert np.all(box[0] >= low - 1e-6) and np.all(box[1] <= high + 1e-6)
    tight = np.stack([drawn[[1, 3]].reshape(-1, 3).min(0), drawn[[1, 3]].reshape(-1, 3).max(0)])
    bell = result.file[fields.BELL_SURFACE_VERTICES.path][[1, 3]].reshape(-1, 3)
    tight = np.stack([np.minimum(tight[0], bell.min(0)), np.maximum(tight[1], bell.max(0))])
    np.testing.assert_allclose(low, tight[0], atol=look.tentacle_radius + 1e-6)
    np.testing.assert_allclose(high, tight[1], atol=look.tentacle_radius + 1e-6)


def _rotation_xyz(angles: list[float]) -> np.ndarray:
    x, y, z = angles
    rx = np.array([[1, 0, 0], [0, np.cos(x), -np.sin(x)], [0, np.sin(x), np.cos(x)]])
    ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    rz = np.array([[np.cos(z), -np.sin(z), 0], [np.sin(z), np.cos(z), 0], [0, 0, 1]])
    return rz @ ry @ rx  # Blender's XYZ Euler order


def test_the_camera_follows_the_path_of_jellysim_render(blender_export) -> None:
    stage_path, _, script, result = blender_export
    settings = script.read_stage_settings(stage_path)
    width, height = script.RESOLUTION
    view = script.camera_placement(settings, width / height)
    members = make_members([result], 1, 2, 0, fluid=False)
    cameras, _, _ = frame_cameras(members, result.frames, (width, height), "follow")
    np.testing.assert_allclose(view["first"], cameras[1].location, atol=1e-9)  # frames 1 to 3
    np.testing.assert_allclose(view["last"], cameras[3].location, atol=1e-9)
    np.testing.assert_allclose(view["direction"], VIEW_DIRECTION / np.linalg.norm(VIEW_DIRECTION))
    assert view["angle"] == pytest.approx(np.radians(FIELD_OF_VIEW))
    rotation = _rotation_xyz(script.camera_rotation(view["direction"]))
    forward, up = rotation @ [0.0, 0.0, -1.0], rotation @ [0.0, 1.0, 0.0]
    np.testing.assert_allclose(forward, view["direction"], atol=1e-12)
    assert up[2] > 0.0 and abs(np.dot(rotation @ [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])) < 1e-12
    # The jellysim stays within the clip range at every exported frame.
    for frame, location in ((1, view["first"]), (3, view["last"])):
        target = np.array(script.camera_target(settings, frame))
        depth = (target - location) @ forward
        assert view["clip_start"] < depth - np.linalg.norm(settings["camera_half"])
        assert depth + np.linalg.norm(settings["camera_half"]) < view["clip_end"]


def test_materials_lights_and_render_settings(blender_export) -> None:
    stage_path, _, script, result = blender_export
    settings = script.read_stage_settings(stage_path)
    look = scene_look(result.scene)
    materials = script.material_parameters(settings)
    np.testing.assert_allclose(materials["Bell"]["base_color"], [*look.bell_color, 1.0])
    assert materials["Bell"]["alpha"] == pytest.approx(1.0 - look.bell_transparency)
    assert materials["Bell"]["transmission"] == pytest.approx(look.bell_transparency)
    assert materials["Bell"]["ior"] == pytest.approx(bell_material(look).ior)
    assert materials["Bell"]["roughness"] == pytest.approx(bell_material(look).roughness)
    assert materials["Tentacles"]["roughness"] == pytest.approx(tentacle_material(look).roughness)
    emitted = np.multiply(
        materials["Bell"]["emission_strength"], materials["Bell"]["emission_color"]
    )
    np.testing.assert_allclose(emitted[:3], bell_material(look).emissive)
    assert materials["Bell"]["blend"] and not materials["Tentacles"]["blend"]
    np.testing.assert_allclose(materials["Tentacles"]["base_color"], [*look.tentacle_color, 1.0])
    np.testing.assert_allclose(materials["World"]["color"], [*look.water_color, 1.0])

    frame = script.render_settings(settings)
    assert (frame["frame_start"], frame["frame_end"], frame["frame_step"]) == (1, 3, 2)
    assert frame["fps"] / frame["fps_base"] == pytest.approx(10.0)
    assert (frame["resolution_x"], frame["resolution_y"]) == script.RESOLUTION
    assert script.render_settings(settings, (64, 48))["resolution_x"] == 64
    ntsc = script.render_settings({**settings, "fps": 30000 / 1001})
    assert (ntsc["fps"], ntsc["fps"] / ntsc["fps_base"]) == (30, pytest.approx(29.97, abs=1e-3))

    for light in script.light_rig(settings["camera_half"], 1.0):
        assert light["energy"] > 0.0
        if light["type"] == "AREA":  # beside the camera, up and to the left, as its child
            assert light["camera_offset"][0] < 0.0 < light["camera_offset"][1]
        else:
            aim = _rotation_xyz(light["rotation"]) @ [0.0, 0.0, -1.0]  # along local -z
            assert aim[2] < 0.0  # the sun shines downwards
    assert script.curve_bevel_depth(1.0, 0.002) == 0.002  # radii not imported: the bevel's
    assert script.curve_bevel_depth(0.002, 0.002) == 1.0  # radii imported in metres
