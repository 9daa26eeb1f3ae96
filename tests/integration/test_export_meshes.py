"""``jellysim export --format obj|ply``: frame sequences read back (meshio for triangles and
points, a line parser for OBJ polylines) and compared with result.h5."""

from __future__ import annotations

from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest

import jellysim
from jellysim import fields
from jellysim.export import export
from jellysim.export.gltf import TUBE_SIDES, tube_faces
from jellysim.interpolation import interpolate_result


@pytest.fixture(scope="module")
def brown(tmp_path_factory: pytest.TempPathFactory) -> jellysim.Result:
    folder = tmp_path_factory.mktemp("brown")
    # brown-jelly's marginal tentacles alone (the oral arms are a second group: the exports of
    # groups are tests/integration/test_export_groups.py's), 60 particles a tentacle: the counts
    # below assume them (the preset has 90 since issue 25).
    overrides = {"duration": 0.4, "fps": 10.0, "tentacles.particles": 60}
    scene = jellysim.load_scene("brown-jelly", overrides).group_scene(0)
    return jellysim.run(scene, folder)


def _obj_vertices(path: Path) -> np.ndarray:
    return np.array(
        [[float(v) for v in line.split()[1:]] for line in path.read_text().splitlines()
         if line.startswith("v ")]
    )  # fmt: skip


def test_obj_sequence_holds_the_bell_and_every_drawn_tentacle_as_a_tube(
    brown: jellysim.Result, tmp_path: Path
) -> None:
    first = export(brown, "obj", tmp_path, every=2, interpolation=2, up="z")
    assert first == [tmp_path / "frame_00000.obj"]
    drawn = interpolate_result(brown, 2)
    faces = brown.file[fields.BELL_SURFACE_FACES.path][:]
    rings = TUBE_SIDES * 60 + 2  # a tube's vertices: 60 rings and the two cap centres
    for frame in range(0, brown.frames, 2):
        path = tmp_path / f"frame_{frame:05d}.obj"
        mesh = meshio.read(path)  # every triangle: the bell's, then the tubes'
        bell = brown.file[fields.BELL_SURFACE_VERTICES.path][frame]
        np.testing.assert_array_equal(mesh.cells_dict["triangle"][: len(faces)], faces)
        np.testing.assert_allclose(mesh.points[: len(bell)], bell, rtol=1e-6, atol=1e-9)
        assert len(mesh.cells_dict["triangle"]) == len(faces) + 12 * len(tube_faces(1, 60))
        assert "\nl " not in path.read_text()  # no bare lines, which no renderer draws
        tubes = mesh.points[len(bell) :].reshape(12, rings, 3)
        centres = tubes[:, : TUBE_SIDES * 60].reshape(12, 60, TUBE_SIDES, 3).mean(axis=2)
        np.testing.assert_allclose(centres, drawn[frame], rtol=1e-6, atol=1e-7)
    assert not list(tmp_path.glob("*.tmp"))


def test_obj_is_y_up_by_default(brown: jellysim.Result, tmp_path: Path) -> None:
    """OBJ readers take y as up (Blender's importer, trimesh): jellysim's (x, y, z) is written
    as (x, z, -y), a rotation that keeps the winding; ``up="z"`` keeps jellysim's axes."""
    export(brown, "obj", tmp_path / "y", frames=(3, 4))
    export(brown, "obj", tmp_path / "z", frames=(3, 4), up="z")
    y_up = _obj_vertices(tmp_path / "y" / "frame_00003.obj")
    z_up = _obj_vertices(tmp_path / "z" / "frame_00003.obj")
    np.testing.assert_allclose(y_up, np.stack([z_up[:, 0], z_up[:, 2], -z_up[:, 1]], axis=1))
    # The normals turn with the points, and every face's winding agrees with its normals.
    mesh = meshio.read(tmp_path / "y" / "frame_00003.obj")
    z_normals = meshio.read(tmp_path / "z" / "frame_00003.obj").point_data["obj:vn"]
    normals = mesh.point_data["obj:vn"]
    np.testing.assert_allclose(
        normals, np.stack([z_normals[:, 0], z_normals[:, 2], -z_normals[:, 1]], axis=1), atol=1e-6
    )
    a, b, c = (mesh.points[mesh.cells_dict["triangle"][:, k]] for k in range(3))
    facing = np.cross(b - a, c - a)
    corners = normals[mesh.cells_dict["triangle"]].sum(axis=1)
    assert np.mean(np.sum(facing * corners, axis=1) > 0.0) > 0.99
    assert "(m, y up)" in (tmp_path / "y" / "frame_00003.obj").read_text().splitlines()[0]
    # The bell hangs over its tentacles along the file's up axis.
    bell = len(brown.file[fields.BELL_SURFACE_VERTICES.path][3])
    assert y_up[:bell, 1].mean() > y_up[bell:, 1].mean()


def test_ply_of_a_jellyfish_and_of_a_fluid(brown: jellysim.Result, tmp_path: Path) -> None:
    export(brown, "ply", tmp_path / "jelly", frames=(1, 2))
    mesh = meshio.read(tmp_path / "jelly" / "frame_00001.ply")
    bell = brown.file[fields.BELL_SURFACE_VERTICES.path][1]
    np.testing.assert_allclose(mesh.points[: len(bell)], bell, rtol=1e-6)
    np.testing.assert_array_equal(
        mesh.cells_dict["triangle"], brown.file[fields.BELL_SURFACE_FACES.path][:]
    )
    assert int(np.sum(mesh.point_data["part"] == 1)) == 6 * 10 * 60  # interpolation 10

    folder = tmp_path / "fluid"
    folder.mkdir()
    rng = np.random.default_rng(3)
    alive = np.ones((2, 30), dtype=bool)
    alive[1, :4] = False
    with h5py.File(folder / "result.h5", "w") as f:
        f[fields.TIME.path] = np.array([0.0, 0.1])
        f[fields.FLUID_POSITION.path] = rng.uniform(0, 1, (2, 30, 2))
        f[fields.FLUID_VELOCITY.path] = rng.normal(size=(2, 30, 2))
        f[fields.FLUID_PRESSURE.path] = rng.uniform(0, 100, (2, 30))
        f[fields.FLUID_ALIVE.path] = alive
        f[fields.FLUID_KIND.path] = np.zeros(30, dtype=np.int8)
        f.attrs["scene"] = 'name = "b"\n'
        f.attrs["fps"] = 10.0
        f.attrs["frames_expected"] = 2
    with jellysim.open_result(folder) as result:
        export(result, "ply", tmp_path / "fluid-ply")
        cloud = meshio.read(tmp_path / "fluid-ply" / "frame_00001.ply")
        assert cloud.points.shape == (26, 3)
        np.testing.assert_allclose(
            cloud.points[:, :2], result.file[fields.FLUID_POSITION.path][1, 4:]
        )
        np.testing.assert_allclose(
            cloud.point_data["pressure"], result.file[fields.FLUID_PRESSURE.path][1, 4:]
        )
        np.testing.assert_allclose(
            cloud.point_data["vy"], result.file[fields.FLUID_VELOCITY.path][1, 4:, 1]
        )
