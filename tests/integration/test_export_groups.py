"""Every export of a scene of several tentacle groups (issue 25): purple-jelly's eight marginal
threads and four oral arms drawn as ribbons. Each group its own part, in its own colour, of its
own particle count (no NaN padding in any file); the glTF passes the Khronos validator, the USD
stage USD's validators; the VTK and OBJ files read back."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
from test_export_gltf import Glb, assert_valid

import jellysim
from jellysim import fields
from jellysim.export import export
from jellysim.export.gltf import TUBE_SIDES, tube_faces
from jellysim.export.groups import export_groups
from jellysim.interpolation import interpolate_groups
from jellysim.render.materials import arm_tissue
from jellysim.render.pipeline import scene_look

ARMS_COLOR = (0.0, 0.8, 0.1)  # the arms' colour set for the test, unlike any other


@pytest.fixture(scope="module")
def purple(tmp_path_factory: pytest.TempPathFactory) -> jellysim.Result:
    folder = tmp_path_factory.mktemp("purple")
    return jellysim.run(
        "purple-jelly",
        folder,
        overrides={"duration": 0.2, "fps": 10.0, "tentacles.oral_arms.color": list(ARMS_COLOR)},
    )


def test_the_result_is_padded_and_the_groups_are_not(purple: jellysim.Result) -> None:
    """The premise: the stored chains are NaN-padded, the drawn groups are not."""
    assert np.isnan(purple.read(fields.TENTACLE_POSITION)).any()
    groups = export_groups(purple, scene_look(purple.scene), None)
    assert [(g.name, g.part, g.form) for g in groups] == [
        ("marginal", "tentacles_marginal", "thread"),
        ("oral_arms", "tentacles_oral_arms", "ribbon"),
    ]
    drawn = interpolate_groups(purple)
    for group, reference in zip(groups, drawn, strict=True):
        np.testing.assert_array_equal(group.positions, reference.positions)
        assert np.isfinite(group.positions).all()
    assert groups[1].material.base_color == ARMS_COLOR
    assert groups[0].material.base_color == purple.scene.groups[0].tentacles.color
    arms = groups[1].ribbon_meshes(1)
    assert len(arms.faces) > 0 and np.isfinite(arms.vertices).all()
    np.testing.assert_allclose(np.linalg.norm(arms.normals, axis=1), 1.0, rtol=1e-9)
    assert set(arms.arm.tolist()) == {0, 1, 2, 3}


def test_gltf_has_a_primitive_and_material_per_group(
    purple: jellysim.Result, tmp_path: Path
) -> None:
    *parts, _, _ = export(purple, "gltf", tmp_path)  # the index and the Blender script
    assert_valid(parts)
    glb = Glb(parts[0])
    materials = {m.name: m for m in glb.doc.materials}
    assert set(materials) == {"bell", "tentacles_marginal", "tentacles_oral_arms"}
    arms = materials["tentacles_oral_arms"]
    # The arms' translucent tissue, as POV-Ray and the preview draw them (issue 27).
    opacity = 1.0 - arm_tissue(scene_look(purple.scene)).bell_transparency
    np.testing.assert_allclose(arms.pbrMetallicRoughness.baseColorFactor, [*ARMS_COLOR, opacity])
    assert opacity < 1.0 and arms.alphaMode == "BLEND"
    assert arms.doubleSided
    marginal = purple.scene.groups[0].tentacles
    np.testing.assert_allclose(
        materials["tentacles_marginal"].pbrMetallicRoughness.baseColorFactor,
        [*marginal.color, 1.0],
    )
    assert glb.names() == ["bell", "tentacles_marginal", "tentacles_oral_arms"]
    assert [glb.material(name) for name in glb.names()] == glb.names()
    groups = export_groups(purple, scene_look(purple.scene), None)
    count, particles = groups[0].positions.shape[1:3]
    _, threads = glb.object("tentacles_marginal")
    assert glb.doc.accessors[threads.attributes.POSITION].count == count * (particles * 6 + 2)
    # The arms keep one grid over the frames (the most stations any frame needs): a morph
    # target per frame, the renderers' ribbon surface at those stations.
    frames = glb.frames()
    subdivisions = groups[1].ribbon_subdivisions(range(frames[0], frames[-1] + 1))
    _, ribbons = glb.object("tentacles_oral_arms")
    triangles = glb.array(ribbons.indices).reshape(-1, 3)
    for frame in frames:
        arms = groups[1].ribbon_meshes(frame, subdivisions)
        points = glb.at("tentacles_oral_arms", frame)
        # y up in the file: (x, y, z) -> (x, z, -y).
        np.testing.assert_allclose(points[:, 0], arms.vertices[:, 0], atol=2e-6)
        np.testing.assert_allclose(points[:, 1], arms.vertices[:, 2], atol=2e-6)
        np.testing.assert_allclose(points[:, 2], -arms.vertices[:, 1], atol=2e-6)
        # Every triangle the renderers draw is in the file (theirs drop degenerate ones).
        drawn = {tuple(sorted(t)) for t in arms.faces.tolist()}
        assert drawn <= {tuple(sorted(t)) for t in triangles.tolist()}


def test_usd_has_a_prim_per_group_and_passes_validation(
    purple: jellysim.Result, tmp_path: Path
) -> None:
    pytest.importorskip("pxr", reason="usd-core is a test dependency (pip install -e .[test])")
    from pxr import Usd, UsdGeom, UsdShade, UsdValidation

    path, script_path = export(purple, "usd", tmp_path)
    stage = Usd.Stage.Open(str(path))
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    assert [e.GetMessage() for e in errors] == []
    threads = stage.GetPrimAtPath("/Jellyfish/Tentacles_marginal")
    arms = stage.GetPrimAtPath("/Jellyfish/Tentacles_oral_arms")
    assert threads.IsA(UsdGeom.BasisCurves) and arms.IsA(UsdGeom.Mesh)
    assert not stage.GetPrimAtPath("/Jellyfish/Tentacles").IsValid()
    groups = export_groups(purple, scene_look(purple.scene), None)
    counts = UsdGeom.BasisCurves(threads).GetCurveVertexCountsAttr().Get()
    assert list(counts) == [41] * groups[0].positions.shape[1]
    mesh = UsdGeom.Mesh(arms)
    for frame in (0, purple.frames - 1):
        expected = groups[1].ribbon_meshes(frame)
        points = np.array(mesh.GetPointsAttr().Get(frame))
        np.testing.assert_allclose(points, expected.vertices, atol=1e-6)
        assert len(mesh.GetNormalsAttr().Get(frame)) == len(points)
        assert np.isfinite(np.array(UsdGeom.BasisCurves(threads).GetPointsAttr().Get(frame))).all()
    bound = UsdShade.MaterialBindingAPI(arms).ComputeBoundMaterial()[0]
    shader = UsdShade.Shader(stage.GetPrimAtPath(f"{bound.GetPath()}/PreviewSurface"))
    np.testing.assert_allclose(shader.GetInput("diffuseColor").Get(), ARMS_COLOR, atol=1e-7)
    data = dict(stage.GetRootLayer().customLayerData)["jellysim"]
    assert set(data["materials"]) == {"Bell", "Tentacles_marginal", "Tentacles_oral_arms", "Fluid"}
    np.testing.assert_allclose(
        list(data["materials"]["Tentacles_oral_arms"]["base_color"]), ARMS_COLOR
    )
    # The Blender script gives each group's object its colour (its logic, without Blender).
    spec = importlib.util.spec_from_file_location("import_into_blender", script_path)
    assert spec is not None and spec.loader is not None
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    settings = script.read_stage_settings(path)
    assert settings == script.settings_from_metadata(script.EMBEDDED_SETTINGS)
    parameters = script.material_parameters(settings)
    assert parameters["Tentacles_oral_arms"]["base_color"] == [*ARMS_COLOR, 1.0]
    marginal = purple.scene.groups[0].tentacles.color
    np.testing.assert_allclose(parameters["Tentacles_marginal"]["base_color"], [*marginal, 1.0])
    # The arms in their translucent tissue, the threads opaque (groups' materials).
    arms = parameters["Tentacles_oral_arms"]
    assert arms["alpha"] == pytest.approx(groups[1].material.opacity) and arms["alpha"] < 1.0
    assert arms["blend"] and not parameters["Tentacles_marginal"]["blend"]


def test_vtk_has_a_part_per_group_with_the_group_array(
    purple: jellysim.Result, tmp_path: Path
) -> None:
    import meshio

    pvds = export(purple, "vtk", tmp_path)
    assert {p.name for p in pvds} == {
        "bell.pvd",
        "tentacles_marginal.pvd",
        "tentacles_oral_arms.pvd",
    }
    groups = export_groups(purple, scene_look(purple.scene), None)
    frame = purple.frames - 1
    threads = meshio.read(tmp_path / f"tentacles_marginal_{frame:05d}.vtu")
    count, particles = groups[0].positions.shape[1:3]
    np.testing.assert_allclose(threads.points, groups[0].positions[frame].reshape(-1, 3))
    assert threads.cells[0].type == "line" and len(threads.cells[0].data) == count * (particles - 1)
    assert set(threads.cell_data["group"][0].tolist()) == {0}
    arms = meshio.read(tmp_path / f"tentacles_oral_arms_{frame:05d}.vtu")
    expected = groups[1].ribbon_meshes(frame)
    np.testing.assert_allclose(arms.points, expected.vertices)
    assert arms.cells[0].type == "triangle"
    np.testing.assert_array_equal(arms.cells[0].data, expected.faces)
    assert set(arms.cell_data["group"][0].tolist()) == {1}
    np.testing.assert_allclose(arms.point_data["Normals"], expected.normals)
    for mesh in (threads, arms):
        assert np.isfinite(mesh.points).all()


def test_obj_has_a_group_per_tentacle_group_and_no_nan(
    purple: jellysim.Result, tmp_path: Path
) -> None:
    export(purple, "obj", tmp_path)
    frame = purple.frames - 1
    text = (tmp_path / f"frame_{frame:05d}.obj").read_text()
    assert "nan" not in text.lower()
    lines = text.splitlines()
    assert [line for line in lines if line[:2] in ("o ", "g ")] == [
        "o bell",
        "o tentacles_marginal",
        "g marginal",
        "o tentacles_oral_arms",
        "g oral_arms",
    ]
    assert "mtllib materials.mtl" in lines and "usemtl tentacles_oral_arms" in lines
    mtl = (tmp_path / "materials.mtl").read_text().splitlines()
    arms = mtl.index("newmtl tentacles_oral_arms")
    assert [float(v) for v in mtl[arms + 1].split()[1:]] == list(ARMS_COLOR)
    # Every index in range; the threads as tubes of 41 rings, the arms' faces, all with normals.
    vertices = sum(line.startswith("v ") for line in lines)
    normals = sum(line.startswith("vn ") for line in lines)
    start = lines.index("o tentacles_oral_arms")
    threads_start = lines.index("o tentacles_marginal")
    groups = export_groups(purple, scene_look(purple.scene), None)
    drawn = groups[0].positions.shape[1]
    thread_faces = [line for line in lines[threads_start:start] if line.startswith("f ")]
    assert len(thread_faces) == drawn * len(tube_faces(1, 41))
    assert not any(line.startswith("l ") for line in lines)
    faces = [line.split()[1:] for line in lines[start:] if line.startswith("f ")]
    assert len(faces) == len(groups[1].ribbon_meshes(frame).faces)
    every = [line.split()[1:] for line in lines if line.startswith("f ")][-len(faces) - 1 :]
    for corner in (c for face in every for c in face):
        v, n = corner.split("//")
        assert 1 <= int(v) <= vertices and 1 <= int(n) <= normals
    arms_normals = len(groups[1].ribbon_meshes(frame).vertices)
    bell = purple.file[fields.BELL_SURFACE_VERTICES.path].shape[1]
    assert normals == vertices == bell + arms_normals + drawn * (TUBE_SIDES * 41 + 2)


def test_ply_points_are_finite(purple: jellysim.Result, tmp_path: Path) -> None:
    import meshio

    export(purple, "ply", tmp_path)
    mesh = meshio.read(tmp_path / "frame_00000.ply")
    groups = export_groups(purple, scene_look(purple.scene), None)
    tentacle_points = sum(math.prod(g.positions.shape[1:3]) for g in groups)
    assert int((mesh.point_data["part"] == 1).sum()) == tentacle_points
    assert np.isfinite(mesh.points).all()


def test_the_gltf_json_allowance_grows_with_the_groups(
    purple: jellysim.Result, tmp_path: Path
) -> None:
    """What a frame of two groups adds to a part's JSON stays within the planned allowance."""
    from jellysim.export import gltf as gltf_export

    def json_length(frames: tuple[int, int]) -> int:
        part = export(purple, "gltf", tmp_path / f"{frames}", frames=frames)[0]
        return int.from_bytes(part.read_bytes()[12:16], "little")

    one, all_frames = json_length((0, 1)), json_length((0, purple.frames))
    allowance = gltf_export.JSON_BYTES_PER_FRAME + gltf_export.JSON_BYTES_PER_GROUP
    assert one < gltf_export.JSON_BYTES_FIXED
    assert (all_frames - one) / (purple.frames - 1) < allowance
