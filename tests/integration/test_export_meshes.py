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


def _obj_polylines(path: Path) -> tuple[np.ndarray, list[list[int]]]:
    vertices, lines = [], []
    for line in path.read_text().splitlines():
        if line.startswith("v "):
            vertices.append([float(v) for v in line.split()[1:]])
        elif line.startswith("l "):
            lines.append([int(v) - 1 for v in line.split()[1:]])
    return np.array(vertices), lines


def test_obj_sequence_holds_the_bell_and_every_drawn_tentacle(
    brown: jellysim.Result, tmp_path: Path
) -> None:
    first = export(brown, "obj", tmp_path, every=2, interpolation=2)
    assert first == [tmp_path / "frame_00000.obj"]
    drawn = interpolate_result(brown, 2)
    faces = brown.file[fields.BELL_SURFACE_FACES.path][:]
    for frame in range(0, brown.frames, 2):
        path = tmp_path / f"frame_{frame:05d}.obj"
        mesh = meshio.read(path)  # the triangles
        bell = brown.file[fields.BELL_SURFACE_VERTICES.path][frame]
        np.testing.assert_array_equal(mesh.cells_dict["triangle"], faces)
        np.testing.assert_allclose(mesh.points[: len(bell)], bell, rtol=1e-6, atol=1e-9)
        vertices, lines = _obj_polylines(path)
        assert len(lines) == 12 and all(len(line) == 60 for line in lines)
        tentacles = np.array([vertices[line] for line in lines])
        np.testing.assert_allclose(tentacles, drawn[frame], rtol=1e-6, atol=1e-8)
    assert not list(tmp_path.glob("*.tmp"))


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
