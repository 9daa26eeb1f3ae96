"""One look everywhere (issue 27): for two presets of different looks and two tentacle groups
each (brown-jelly: dark reddish-brown marginal tentacles and cream oral arms on a golden-brown
bell; purple-jelly: magenta threads and mauve arms on a mauve bell), every output is read back
and its bell's and each group's colour compared with the one resolution of ``[look]``
(:mod:`jellysim.render.materials`: ``bell_material``, ``group_look``): the glTF materials'
``baseColorFactor``, the USD UsdPreviewSurface ``diffuseColor`` (and ``displayColor``), the OBJ
export's ``materials.mtl`` ``Kd``, the viewer's /meta.json (what viewer.js colours with) and
POV-Ray's scene text.

Convention: colours are linear RGB everywhere they are stored (scene files, glTF, USD, MTL,
meta.json, POV-Ray with ``assumed_gamma 1.0``); a ``#rrggbb`` value in a scene is sRGB and is
decoded to linear when read. VTK carries no colours.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from test_export_gltf import Glb

import jellysim
from jellysim.export import export
from jellysim.render import povray
from jellysim.render.frame import Frame
from jellysim.render.materials import bell_material, group_look, srgb
from jellysim.render.pipeline import frame_cameras, make_members, scene_look
from jellysim.view.server import ResultData

POV_DIGITS = 5e-4  # POV-Ray's scene text writes colours with 4 significant digits
NUMBER = r"-?[\d.]+(?:e-?\d+)?"

# The presets' looks as their files comment them in sRGB (the scene stores linear values).
SRGB_COMMENTS = {
    "brown-jelly": {"oral_arms": "#f0dcb4"},
    "purple-jelly": {"marginal": "#96286e", "oral_arms": "#d28cc8"},
}


@pytest.fixture(scope="module", params=["brown-jelly", "purple-jelly"])
def result(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.mktemp(request.param)
    scene = jellysim.load_scene(request.param, {"duration": 0.1, "fps": 10.0})
    assert [g.name for g in scene.groups] == ["marginal", "oral_arms"]
    return jellysim.run(scene, folder)


@pytest.fixture(scope="module")
def expected(result: jellysim.Result) -> dict[str, np.ndarray]:
    """Linear RGB per object: the bell and each group, from the one resolution of [look]."""
    look = scene_look(result.scene)
    colors = {"bell": np.asarray(bell_material(look).base_color)}
    for group in result.scene.groups:
        colors[group.name] = np.asarray(group_look(look, group.tentacles, group.name).color)
    return colors


def test_the_two_looks_differ(expected) -> None:
    # brown-jelly's reddish-brown against purple-jelly's magenta: the presets really differ.
    assert len(expected) == 3
    assert expected["marginal"][0] > expected["marginal"][2]  # both red-dominant, so
    assert not np.allclose(expected["bell"], expected["marginal"])


def test_hex_colours_are_srgb_decoded_to_linear(result: jellysim.Result, expected) -> None:
    for name, hex_color in SRGB_COMMENTS[result.scene.name].items():
        encoded = np.array([int(hex_color[i : i + 2], 16) / 255 for i in (1, 3, 5)])
        # The preset's linear value (two decimals) encodes to its sRGB comment within a few
        # steps of 8 bits (two decimals of a dark linear value span several sRGB steps)...
        np.testing.assert_allclose(srgb(expected[name]), encoded, atol=3.0 / 255)
        # ... and the hex value itself, given in a scene, is read as that same colour.
        key = f"tentacles.{name}.color"
        scene = jellysim.load_scene(result.scene.name, {key: hex_color})
        group = next(g for g in scene.groups if g.name == name)
        np.testing.assert_allclose(srgb(np.asarray(group.tentacles.color)), encoded, atol=1e-12)


def test_gltf(result: jellysim.Result, expected, tmp_path: Path) -> None:
    glb = Glb(export(result, "gltf", tmp_path, interpolation=1)[0])
    for name, color in expected.items():
        part = name if name == "bell" else f"tentacles_{name}"
        material = glb.doc.materials[glb.object(part)[1].material]
        np.testing.assert_allclose(material.pbrMetallicRoughness.baseColorFactor[:3], color)


def test_usd(result: jellysim.Result, expected, tmp_path: Path) -> None:
    pytest.importorskip("pxr", reason="usd-core is a test dependency (pip install -e .[test])")
    from pxr import Usd, UsdGeom, UsdShade

    path, _ = export(result, "usd", tmp_path, interpolation=1)
    stage = Usd.Stage.Open(str(path))
    for name, color in expected.items():
        prim = stage.GetPrimAtPath(
            "/Jellyfish/" + ("Bell" if name == "bell" else f"Tentacles_{name}")
        )
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        shader = material.ComputeSurfaceSource()[0]
        np.testing.assert_allclose(shader.GetInput("diffuseColor").Get(), color, atol=1e-6)
        display = UsdGeom.Gprim(prim).GetDisplayColorAttr().Get()
        np.testing.assert_allclose(display[0], color, atol=1e-6)


def test_obj_materials(result: jellysim.Result, expected, tmp_path: Path) -> None:
    export(result, "obj", tmp_path, interpolation=1)
    text = (tmp_path / "materials.mtl").read_text()
    kd = {
        name: np.array(values.split(), dtype=float)
        for name, values in re.findall(r"newmtl (\S+)\nKd ([^\n]+)", text)
    }
    assert "linear RGB" in text
    for name, color in expected.items():
        part = name if name == "bell" else f"tentacles_{name}"
        np.testing.assert_allclose(kd[part], color, atol=1e-6)  # 6 significant digits


def test_viewer(result: jellysim.Result, expected) -> None:
    meta = ResultData(result).meta()
    np.testing.assert_allclose(meta["look"]["bell_color"], expected["bell"], atol=1e-12)
    groups = {g["name"]: g for g in meta["tentacles"]["groups"]}
    for name in ("marginal", "oral_arms"):
        np.testing.assert_allclose(groups[name]["color"], expected[name], atol=1e-12)
    # viewer.js reads these as linear (THREE.LinearSRGBColorSpace) and lets three.js encode.
    viewer = Path(jellysim.__file__).parent / "view" / "static" / "viewer.js"
    source = viewer.read_text()
    assert "THREE.LinearSRGBColorSpace" in source
    assert "linear(group.color)" in source and "linear(look.bell_color)" in source


def test_povray(result: jellysim.Result, expected) -> None:
    (member,) = make_members([result], 1, None, 0, fluid=False)
    cameras, extent, _ = frame_cameras([member], result.frames, (64, 48), "auto")
    text = povray.scene_text(
        Frame(0.0, [member.frame(0)]), cameras[0], (64, 48), povray.QUALITIES["draft"], extent
    )
    assert "assumed_gamma 1.0" in text  # POV-Ray computes in linear RGB
    found = re.findall(rf"rgbt? <({NUMBER}),({NUMBER}),({NUMBER})", text)
    colors = np.array(found, dtype=np.float64)
    for name, color in expected.items():
        # Each object's own colour is written (face-on for the bell and the ribbons, at the
        # silhouette for the thread tubes).
        assert np.any(np.all(np.abs(colors - color) <= POV_DIGITS, axis=1)), name
