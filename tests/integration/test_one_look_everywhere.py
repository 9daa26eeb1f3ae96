"""One look everywhere (issue 27): for two presets of different looks and two tentacle groups
each (brown-jelly: dark reddish-brown marginal threads and cream oral-arm ribbons on a
golden-brown bell; purple-jelly: magenta threads and mauve arms on a mauve bell), every output is
read back and each object's material (the bell, each group) compared with the one resolution of
``[look]`` in :mod:`jellysim.render.materials` (``bell_material``, ``group_look``,
``group_material``), tied to that object:

- glTF: the material of the node named ``bell`` / ``tentacles_NAME``: ``baseColorFactor`` (colour
  and opacity), ``alphaMode`` BLEND where translucent, ``roughnessFactor``, ``emissiveFactor``.
  No ior: glTF's core material has none (``KHR_materials_ior`` is not written).
- USD: the UsdPreviewSurface bound to ``/Jellyfish/Bell`` / ``Tentacles_NAME``: ``diffuseColor``,
  ``opacity``, ``roughness``, ``emissiveColor``, ``ior``; and the prim's ``displayColor`` and
  ``displayOpacity``.
- OBJ: the ``usemtl`` of object ``bell`` / group ``NAME`` in a frame's OBJ, and that material's
  ``Kd``, ``d``, ``Ke``, ``Pr``, ``Ni`` in ``materials.mtl``.
- Viewer: /meta.json, and in headless Chromium the three.js material each drawn object gets
  (``window.jellysimView.materials``): the bell a translucent Phong material (colour, emissive,
  opacity, shininess = ``phong_shininess`` of its roughness), a ribbon group the same, a thread
  group lines in its face-on colour (``tentacle_face_color``: lines face the camera), which
  carry no emission or shininess (threads have none to carry). No ior: no refraction.
- POV-Ray: each object's block (after its ``// object NAME`` comment) at final quality: the
  pigment's face-on colour and transmit (the ``aoi`` map at 1: ``bell_transmit`` face-on of the
  bell's or the arms' tissue, the rim's clearing on top of ``1 - opacity``), ``emission`` (its
  fraction of the pigment's colour), the bell's ``ior``; threads their colour at the silhouette
  and face-on colour. POV-Ray's ``roughness`` is the size of a Phong highlight, not the PBR
  roughness, so it is not compared.
- Blender: checked in ``tests/integration/test_blender_import.py`` (the import script under
  bpy; each object's Principled BSDF read back from the saved .blend, USD and glTF routes).

Convention: colours are linear RGB everywhere they are stored (scene files, glTF, USD, MTL,
meta.json, three.js in ``LinearSRGBColorSpace``, POV-Ray with ``assumed_gamma 1.0``); a
``#rrggbb`` value in a scene is sRGB and is decoded to linear when read. VTK carries no
materials.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_export_gltf import Glb
from viewing import serving

import jellysim
from jellysim.export import export
from jellysim.render import povray
from jellysim.render.frame import Frame
from jellysim.render.materials import (
    Material,
    arm_tissue,
    bell_material,
    bell_transmit,
    group_look,
    group_material,
    phong_shininess,
    srgb,
    tentacle_face_color,
)
from jellysim.render.pipeline import frame_cameras, make_members, scene_look
from jellysim.view.server import ResultData

POV_DIGITS = 5e-4  # POV-Ray's scene text writes colours with 4 significant digits
POV_TRANSMIT = 5e-3  # ... transmit with 3, emission fractions with 3
NUMBER = r"-?[\d.]+(?:e-?\d+)?"
CHROMIUM = "/usr/bin/chromium"
REPOSITORY = Path(__file__).resolve().parents[2]

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
    assert [g.tentacles.form or "thread" for g in scene.groups] == ["thread", "ribbon"]
    return jellysim.run(scene, folder)


@pytest.fixture(scope="module")
def expected(result: jellysim.Result) -> dict[str, Material]:
    """The material per object, the bell and each group, from the one resolution of [look]."""
    look = scene_look(result.scene)
    materials = {"bell": bell_material(look)}
    for group in result.scene.groups:
        drawn = group_look(look, group.tentacles, group.name)
        materials[group.name] = group_material(look, drawn, group.name)
    return materials


def _part(name: str) -> str:
    return name if name == "bell" else f"tentacles_{name}"


def test_the_materials_differ_where_the_objects_do(result: jellysim.Result, expected) -> None:
    look = scene_look(result.scene)
    bell, threads, arms = expected["bell"], expected["marginal"], expected["oral_arms"]
    assert threads.base_color[0] > threads.base_color[2]  # both presets' threads red-dominant
    assert not np.allclose(bell.base_color, threads.base_color)
    # Translucent, glowing, refracting mesoglea; opaque dull threads; arms of the bell's tissue.
    assert 0.0 < bell.opacity < 1.0 and max(bell.emissive) > 0.0 and bell.ior > 1.0
    assert threads.opacity == 1.0 and max(threads.emissive) == 0.0 and threads.ior == 1.0
    assert bell.opacity < arms.opacity < 1.0 and max(arms.emissive) > 0.0
    assert threads.roughness > bell.roughness == arms.roughness
    assert arms.opacity == pytest.approx(1.0 - arm_tissue(look).bell_transparency)


def test_hex_colours_are_srgb_decoded_to_linear(result: jellysim.Result, expected) -> None:
    for name, hex_color in SRGB_COMMENTS[result.scene.name].items():
        encoded = np.array([int(hex_color[i : i + 2], 16) / 255 for i in (1, 3, 5)])
        # The preset's linear value (two decimals) encodes to its sRGB comment within a few
        # steps of 8 bits (two decimals of a dark linear value span several sRGB steps)...
        np.testing.assert_allclose(srgb(expected[name].base_color), encoded, atol=3.0 / 255)
        # ... and the hex value itself, given in a scene, is read as that same colour.
        key = f"tentacles.{name}.color"
        scene = jellysim.load_scene(result.scene.name, {key: hex_color})
        group = next(g for g in scene.groups if g.name == name)
        np.testing.assert_allclose(srgb(np.asarray(group.tentacles.color)), encoded, atol=1e-12)


def test_gltf(result: jellysim.Result, expected, tmp_path: Path) -> None:
    glb = Glb(export(result, "gltf", tmp_path, interpolation=1)[0])
    for name, want in expected.items():
        _, primitive = glb.object(_part(name))  # the node and mesh named so
        material = glb.doc.materials[primitive.material]
        pbr = material.pbrMetallicRoughness
        np.testing.assert_allclose(pbr.baseColorFactor[:3], want.base_color)
        assert pbr.baseColorFactor[3] == pytest.approx(want.opacity)
        assert (material.alphaMode == "BLEND") == (want.opacity < 1.0), name
        assert pbr.roughnessFactor == pytest.approx(want.roughness)
        assert pbr.metallicFactor == 0.0
        emissive = material.emissiveFactor or [0.0, 0.0, 0.0]  # glTF's default: none
        np.testing.assert_allclose(emissive, want.emissive)


def test_usd(result: jellysim.Result, expected, tmp_path: Path) -> None:
    pytest.importorskip("pxr", reason="usd-core is a test dependency (pip install -e .[test])")
    from pxr import Usd, UsdGeom, UsdShade

    path, _ = export(result, "usd", tmp_path, interpolation=1)
    stage = Usd.Stage.Open(str(path))
    for name, want in expected.items():
        prim = stage.GetPrimAtPath(
            "/Jellyfish/" + ("Bell" if name == "bell" else f"Tentacles_{name}")
        )
        assert prim.IsValid(), name
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        shader = material.ComputeSurfaceSource()[0]
        assert shader.GetIdAttr().Get() == "UsdPreviewSurface"

        def get(key: str, shader: UsdShade.Shader = shader) -> object:
            return shader.GetInput(key).Get()

        np.testing.assert_allclose(get("diffuseColor"), want.base_color, atol=1e-6)
        np.testing.assert_allclose(get("emissiveColor"), want.emissive, atol=1e-6)
        assert get("opacity") == pytest.approx(want.opacity, abs=1e-6)
        assert get("roughness") == pytest.approx(want.roughness, abs=1e-6)
        assert get("ior") == pytest.approx(want.ior, abs=1e-6)
        gprim = UsdGeom.Gprim(prim)
        np.testing.assert_allclose(gprim.GetDisplayColorAttr().Get()[0], want.base_color, atol=1e-6)
        assert gprim.GetDisplayOpacityAttr().Get()[0] == pytest.approx(want.opacity, abs=1e-6)


def test_obj_materials(result: jellysim.Result, expected, tmp_path: Path) -> None:
    export(result, "obj", tmp_path, interpolation=1)
    text = (tmp_path / "materials.mtl").read_text()
    assert "linear RGB" in text
    materials: dict[str, dict[str, np.ndarray]] = {}
    for block in re.split(r"^newmtl ", text, flags=re.M)[1:]:
        name, *lines = block.strip().splitlines()
        materials[name] = {
            k: np.array(v.split(), dtype=float) for k, v in (s.split(" ", 1) for s in lines)
        }
    # Which material each object of a frame's OBJ uses: `o bell` / `g NAME`, then `usemtl`.
    frame = sorted(tmp_path.glob("*.obj"))[0].read_text()
    used = dict(re.findall(r"^[og] (\S+)\nusemtl (\S+)$", frame, flags=re.M))
    for name, want in expected.items():
        mtl = materials[used[name]]
        np.testing.assert_allclose(mtl["Kd"], want.base_color, atol=1e-6)  # 6 significant digits
        np.testing.assert_allclose(mtl["Ke"], want.emissive, atol=1e-6)
        np.testing.assert_allclose(mtl["d"], [want.opacity], atol=1e-6)
        np.testing.assert_allclose(mtl["Pr"], [want.roughness], atol=1e-6)
        np.testing.assert_allclose(mtl["Ni"], [want.ior], atol=1e-6)


def _viewer_expected(result: jellysim.Result, expected) -> dict[str, dict[str, object]]:
    """What three.js material each drawn object should get, from the shared materials."""
    look = scene_look(result.scene)
    out: dict[str, dict[str, object]] = {}
    for name, want in expected.items():
        ribbon = name == "bell" or want.opacity < 1.0  # the bell and the arms: lit, translucent
        if ribbon:
            out[name] = {
                "type": "MeshPhongMaterial",
                "color": want.base_color,
                "emissive": want.emissive,
                "opacity": want.opacity,
                "transparent": True,
                "shininess": phong_shininess(want),
            }
        else:  # threads as lines, facing the camera: the face-on colour, opaque
            face = tentacle_face_color(replace(look, tentacle_color=want.base_color))
            out[name] = {
                "type": "LineBasicMaterial",
                "color": face,
                "emissive": None,
                "opacity": 1.0,
                "transparent": False,
                "shininess": None,
            }
    return out


def _assert_viewer_material(got: dict[str, object], want: dict[str, object], name: str) -> None:
    assert got["type"] == want["type"], name
    for key in ("color", "emissive"):
        if want[key] is None:
            assert got[key] is None, (name, key)
        else:
            np.testing.assert_allclose(got[key], want[key], atol=1e-6, err_msg=f"{name} {key}")
    for key in ("opacity", "shininess"):
        if want[key] is None:
            assert got[key] is None, (name, key)
        else:
            assert got[key] == pytest.approx(want[key], abs=1e-6), (name, key)
    assert got["transparent"] == want["transparent"], name


def test_viewer_meta(result: jellysim.Result, expected) -> None:
    """/meta.json carries each object's material; viewer.js builds the three.js material from
    exactly these fields (what it builds is checked in Chromium below)."""
    look = scene_look(result.scene)
    meta = ResultData(result).meta()
    bell = expected["bell"]
    np.testing.assert_allclose(meta["look"]["bell_color"], bell.base_color, atol=1e-12)
    np.testing.assert_allclose(meta["look"]["bell_emissive"], bell.emissive, atol=1e-12)
    assert 1.0 - meta["look"]["bell_transparency"] == pytest.approx(bell.opacity)
    assert meta["look"]["bell_shininess"] == pytest.approx(phong_shininess(bell))
    groups = {g["name"]: g for g in meta["tentacles"]["groups"]}
    for name in ("marginal", "oral_arms"):
        want = expected[name]
        np.testing.assert_allclose(groups[name]["color"], want.base_color, atol=1e-12)
        np.testing.assert_allclose(groups[name]["emissive"], want.emissive, atol=1e-12)
        assert groups[name]["opacity"] == pytest.approx(want.opacity)
        assert groups[name]["shininess"] == pytest.approx(phong_shininess(want))
        face = tentacle_face_color(replace(look, tentacle_color=want.base_color))
        np.testing.assert_allclose(groups[name]["face_color"], face, atol=1e-12)


def test_viewer_draws_each_object_in_its_material(result: jellysim.Result, expected) -> None:
    node = shutil.which("node")
    modules = REPOSITORY / "web" / "node_modules"  # playwright-core: make web, for the tests
    if node is None or not (modules / "playwright-core").is_dir() or not Path(CHROMIUM).exists():
        if os.environ.get("CI"):
            pytest.fail("the viewer test needs node, web/node_modules and chromium (make test)")
        pytest.skip("node, web/node_modules (make web) or chromium (make chromium) missing")
    script = Path(__file__).with_name("view_materials.mjs")
    with serving(result.folder) as server:
        done = subprocess.run(
            [node, str(script), str(modules), CHROMIUM, server.page_url],
            capture_output=True,
            text=True,
            timeout=120,
        )
    assert done.returncode == 0, done.stdout + done.stderr
    drawn = json.loads(done.stdout.strip().splitlines()[-1])
    want = _viewer_expected(result, expected)
    assert set(drawn) == set(want), drawn.keys()
    for name in want:
        _assert_viewer_material(drawn[name], want[name], name)


def _objects(text: str) -> dict[str, str]:
    """The scene text's jellyfish objects by name: each ``// object NAME`` comment's block."""
    pieces = re.split(r"^// object (.+)$", text, flags=re.M)
    return {pieces[k].strip(): pieces[k + 1] for k in range(1, len(pieces), 2)}


def _face_on(block: str) -> tuple[np.ndarray, float]:
    """The (colour, transmit) face-on: the ``aoi`` pigment map's entry at 0 (face-on from
    behind, as at 1); with radial stripes its plain colour between stripes (0.3 of a period)."""
    rgbt = rf"rgbt <({NUMBER}),({NUMBER}),({NUMBER}),({NUMBER})>"
    found = re.search(r"aoi pigment_map \{ \[0 (radial [^}]*\}|rgbt <[^>]*>)", block)
    assert found, block[:200]
    entry = found.group(1)
    if entry.startswith("radial"):
        entry = re.search(rf"\[0\.3 ({rgbt})\]", entry).group(1)
    values = np.array(re.fullmatch(rgbt, entry).groups(), dtype=np.float64)
    return values[:3], float(values[3])


def _emission(block: str) -> float:
    found = re.search(rf"finish \{{[^}}]*emission ({NUMBER})", block)
    return float(found.group(1)) if found else 0.0


def test_povray(result: jellysim.Result, expected) -> None:
    look = scene_look(result.scene)
    (member,) = make_members([result], 1, None, 0, fluid=False)
    cameras, extent, _ = frame_cameras([member], result.frames, (64, 48), "auto")
    text = povray.scene_text(
        Frame(0.0, [member.frame(0)]), cameras[0], (64, 48), povray.QUALITIES["final"], extent
    )
    assert "assumed_gamma 1.0" in text  # POV-Ray computes in linear RGB
    objects = _objects(text)
    assert {"bell", "tentacles marginal", "tentacles oral_arms"} <= set(objects)
    tissues = {"bell": look, "oral_arms": arm_tissue(look)}
    for name, want in expected.items():
        block = objects["bell" if name == "bell" else f"tentacles {name}"]
        if name in tissues:  # translucent tissue: the aoi pigment map's face-on entry
            color, transmit = _face_on(block)
            np.testing.assert_allclose(color, want.base_color, atol=POV_DIGITS, err_msg=name)
            face_on, _ = bell_transmit(tissues[name], 1.0)
            assert transmit == pytest.approx(float(face_on), abs=POV_TRANSMIT), name
            # ... whose transmit before the rim's clearing is the material's 1 - opacity
            clear, _ = bell_transmit(replace(tissues[name], rim=0.0), 1.0)
            assert float(clear) == pytest.approx(1.0 - want.opacity), name
            # emission is a fraction of the pigment's colour: colour x fraction = emissive
            np.testing.assert_allclose(
                _emission(block) * np.asarray(want.base_color), want.emissive, atol=POV_TRANSMIT
            )
        else:  # opaque threads: their colour at the silhouette (aoi 0.5), face-on colour else
            colors = re.findall(rf"\[(\S+) rgb <({NUMBER}),({NUMBER}),({NUMBER})>\]", block)
            by_position = {float(c[0]): np.array(c[1:], dtype=np.float64) for c in colors}
            np.testing.assert_allclose(by_position[0.5], want.base_color, atol=POV_DIGITS)
            face = tentacle_face_color(replace(look, tentacle_color=want.base_color))
            np.testing.assert_allclose(by_position[1.0], face, atol=POV_DIGITS)
            assert _emission(block) == 0.0 and want.emissive == (0.0, 0.0, 0.0)
            assert want.opacity == 1.0 and "rgbt" not in block and "interior" not in block
        ior = re.search(rf"interior \{{ ior ({NUMBER})", block)
        assert (float(ior.group(1)) if ior else 1.0) == pytest.approx(want.ior), name
    assert math.isclose(expected["bell"].ior, 1.02)
