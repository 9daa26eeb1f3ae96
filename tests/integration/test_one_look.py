"""One look, every output (issue 25): the bell's and the tentacles' colours of one result are the
same, within each format's rounding, in POV-Ray's scene text, the preview renderer's colour
inputs, the viewer's /meta.json, the USD stage and the glTF file, and all equal the shared
materials of :mod:`jellysim.render.materials` (linear RGB)."""

from __future__ import annotations

import json
import math
import re
import struct
from pathlib import Path

import numpy as np
import pytest

import jellysim
from jellysim import fields
from jellysim.export import export
from jellysim.interpolation import interpolate_result
from jellysim.render import povray
from jellysim.render.frame import Camera, Frame, Jellyfish
from jellysim.render.materials import (
    bell_material,
    bell_transmit,
    stripe_color,
    tentacle_face_color,
    tentacle_material,
)
from jellysim.render.pipeline import scene_look
from jellysim.render.preview import bell_shading, make_view, tentacle_primitives
from jellysim.view.server import ResultData

POV_DIGITS = 5e-4  # POV-Ray's text writes colours with 4 significant digits

NUMBER = r"-?[\d.]+(?:e-?\d+)?"


@pytest.fixture(scope="module")
def brown(tmp_path_factory: pytest.TempPathFactory) -> jellysim.Result:
    folder = tmp_path_factory.mktemp("brown")
    # brown-jelly's marginal tentacles alone: one group, whose exports name their part
    # "tentacles" (a grouped result's parts are named by group: test_export_groups.py)
    scene = jellysim.load_scene("brown-jelly", {"duration": 0.2, "fps": 10.0}).group_scene(0)
    return jellysim.run(scene, folder)


@pytest.fixture(scope="module")
def expected(brown: jellysim.Result) -> dict[str, tuple[float, ...]]:
    look = scene_look(brown.scene)
    assert look.stripes > 0 and look.rim > 0  # the preset exercises stripes and rim
    return {
        "bell": bell_material(look).base_color,
        "bell_emissive": bell_material(look).emissive,
        "tentacles": tentacle_material(look).base_color,
        "tentacle_face": tentacle_face_color(look),
        "stripe": stripe_color(look),
    }


def test_the_shared_materials_are_the_look(brown: jellysim.Result, expected) -> None:
    look = brown.scene.look
    np.testing.assert_allclose(expected["bell"], look.bell_color)
    np.testing.assert_allclose(expected["tentacles"], look.tentacle_color)
    # Brown-jelly's dark reddish-brown tentacles stay darker than its bell in every channel.
    assert np.all(np.asarray(expected["tentacle_face"]) < np.asarray(expected["bell"]))


def _colors(text: str, keyword: str) -> np.ndarray:
    found = re.findall(rf"{keyword} <({NUMBER}),({NUMBER}),({NUMBER})", text)
    return np.array(found, dtype=np.float64)


def _contains(colors: np.ndarray, color: tuple[float, ...], tolerance: float) -> bool:
    return bool(np.any(np.all(np.abs(colors - np.asarray(color)) <= tolerance, axis=1)))


def test_povray(brown: jellysim.Result, expected) -> None:
    look = scene_look(brown.scene)
    drawn = interpolate_result(brown, 1)
    vertices = brown.file[fields.BELL_SURFACE_VERTICES.path][0]
    jelly = Jellyfish(drawn[0], vertices, brown.bell_surface_faces, look)
    camera = Camera(location=np.array([0.0, -1.0, 0.0]), look_at=np.zeros(3))
    text = povray.scene_text(
        Frame(0.0, [jelly]), camera, (64, 48), povray.QUALITIES["draft"], extent=0.5
    )
    bell_text = text[text.index("mesh2 {") :]
    bell_text = bell_text[: bell_text.index("\n}\n")]
    bell_colors = _colors(bell_text, "rgbt")
    face_transmit = float(bell_transmit(look, 1.0)[0])
    # Face-on (no lightening): the plain bell and the stripe, with their transmits.
    assert _contains(bell_colors, expected["bell"], POV_DIGITS)
    assert _contains(bell_colors, expected["stripe"], POV_DIGITS)
    assert f",{face_transmit:.3g}>" in bell_text
    tentacle_text = text[text.index("union {") :]
    tentacle_colors = _colors(tentacle_text[tentacle_text.index("texture") :], "rgb")
    assert _contains(tentacle_colors, expected["tentacles"], POV_DIGITS)  # the tubes' edges
    assert _contains(tentacle_colors, expected["tentacle_face"], POV_DIGITS)  # face-on


def test_preview(brown: jellysim.Result, expected) -> None:
    look = scene_look(brown.scene)
    between_stripes = np.array([math.pi / look.stripes])  # half a stripe period from one
    color, alpha = bell_shading(look, np.array([1.0]), between_stripes)
    np.testing.assert_allclose(color[0], expected["bell"], atol=1e-12)
    assert alpha[0] == pytest.approx(1.0 - float(bell_transmit(look, 1.0)[0]))
    color, _ = bell_shading(look, np.array([1.0]), np.array([0.0]))  # on a stripe
    np.testing.assert_allclose(color[0], expected["stripe"], atol=1e-12)
    # The tentacles: their face-on colour times a grey brightness (the lighting).
    drawn = interpolate_result(brown, 1)
    camera = Camera(location=np.array([0.0, -1.0, -0.2]), look_at=np.array([0.0, 0.0, -0.2]))
    ribbons = tentacle_primitives(drawn[0], look, make_view(camera, 320, 240), 1e-3, 1)
    assert len(ribbons.rgba) > 0
    brightness = ribbons.rgba[:, :3] / np.asarray(expected["tentacle_face"])
    np.testing.assert_allclose(brightness, brightness[:, :1] * np.ones((1, 3)), rtol=1e-9)
    assert np.all((brightness > 0.0) & (brightness <= 1.0 + 1e-12))


def test_viewer_meta(brown: jellysim.Result, expected) -> None:
    look = ResultData(brown).meta()["look"]
    np.testing.assert_allclose(look["bell_color"], expected["bell"], atol=1e-12)
    np.testing.assert_allclose(look["bell_emissive"], expected["bell_emissive"], atol=1e-12)
    np.testing.assert_allclose(look["tentacle_color"], expected["tentacles"], atol=1e-12)
    np.testing.assert_allclose(look["tentacle_face_color"], expected["tentacle_face"], atol=1e-12)
    np.testing.assert_allclose(look["stripe_color"], expected["stripe"], atol=1e-12)


def test_usd(brown: jellysim.Result, expected, tmp_path: Path) -> None:
    pytest.importorskip("pxr", reason="usd-core is a test dependency (pip install -e .[test])")
    from pxr import Usd, UsdShade

    path, _ = export(brown, "usd", tmp_path, interpolation=1)
    stage = Usd.Stage.Open(str(path))
    for prim, key in (("Bell", "bell"), ("Tentacles", "tentacles")):
        geometry = stage.GetPrimAtPath(f"/Jellyfish/{prim}")
        material, _ = UsdShade.MaterialBindingAPI(geometry).ComputeBoundMaterial()
        shader = material.ComputeSurfaceSource()[0]
        diffuse = shader.GetInput("diffuseColor").Get()
        np.testing.assert_allclose(diffuse, expected[key], atol=1e-6)  # float32


def test_gltf(brown: jellysim.Result, expected, tmp_path: Path) -> None:
    paths = export(brown, "gltf", tmp_path, interpolation=1)
    data = paths[0].read_bytes()
    (length,) = struct.unpack_from("<I", data, 12)  # the JSON chunk follows the 12-byte header
    document = json.loads(data[20 : 20 + length])
    materials = {m["name"]: m for m in document["materials"]}
    for key in ("bell", "tentacles"):
        factor = materials[key]["pbrMetallicRoughness"]["baseColorFactor"]
        np.testing.assert_allclose(factor[:3], expected[key], atol=1e-12)
    np.testing.assert_allclose(materials["bell"]["emissiveFactor"], expected["bell_emissive"])
