"""``jellysim export DIR --format vtk``: VTU files per frame and part, read back with meshio and
compared with result.h5; the .pvd index lists them at the frame times."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest
import scenes

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
    overrides = {"duration": 0.5, "fps": 10.0, "tentacles.particles": 60}
    scene = jellysim.load_scene("brown-jelly", overrides).group_scene(0)
    return jellysim.run(scene, folder)


def _pvd(path: Path) -> list[tuple[float, str]]:
    return [(float(d.attrib["timestep"]), d.attrib["file"]) for d in ET.parse(path).iter("DataSet")]


def test_tentacles_and_bell_round_trip(brown: jellysim.Result, tmp_path: Path) -> None:
    paths = export(brown, "vtk", tmp_path, every=2, interpolation=3)
    assert sorted(p.name for p in paths) == ["bell.pvd", "tentacles.pvd"]
    entries = _pvd(tmp_path / "tentacles.pvd")
    frames = list(range(0, brown.frames, 2))
    np.testing.assert_allclose([t for t, _ in entries], brown.time[frames])
    drawn = interpolate_result(brown, 3)
    faces = brown.file[fields.BELL_SURFACE_FACES.path][:]
    for frame, (_, name) in zip(frames, entries, strict=True):
        mesh = meshio.read(tmp_path / name)
        np.testing.assert_allclose(mesh.points, drawn[frame].reshape(-1, 3), atol=1e-12)
        lines = mesh.cells_dict["line"]
        assert lines.shape == (18 * 59, 2)  # 6 x 3 drawn tentacles of 60 particles
        np.testing.assert_array_equal(np.unique(mesh.point_data["tentacle"]), np.arange(18))
        bell = meshio.read(tmp_path / f"bell_{frame:05d}.vtu")
        np.testing.assert_allclose(
            bell.points, brown.file[fields.BELL_SURFACE_VERTICES.path][frame]
        )
        np.testing.assert_array_equal(bell.cells_dict["triangle"], faces)


# A small soft bell in its tank (issue 6's test scale): three frames.
SMALL_MOON = {**scenes.SMALL_MOON, "duration": 0.2, "fps": 10.0, "tentacles.count": 2}


def test_mass_spring_bell_round_trip(tmp_path: Path) -> None:
    """The soft bell's particles and springs, its surface, the fluid without the bell's rows and
    the drawn tentacles (the preset's two groups: the marginal fringe and the oral arms, one
    series each), read back with meshio at every frame."""
    moon = jellysim.run("moon-jelly", tmp_path / "moon", overrides=SMALL_MOON)
    out = tmp_path / "vtk"
    paths = export(moon, "vtk", out, interpolation=2)
    assert sorted(p.name for p in paths) == [
        "bell.pvd", "bell_particles.pvd", "fluid.pvd",
        "tentacles_marginal.pvd", "tentacles_oral_arms.pvd",
    ]  # fmt: skip
    f = moon.file
    pairs = f[fields.BELL_SPRINGS.path][:]
    muscle = f[fields.BELL_MUSCLE.path][:]
    rest = f[fields.BELL_REST_POSITION.path][:]
    assert 0 < muscle.sum() < len(pairs)
    entries = _pvd(out / "bell_particles.pvd")
    np.testing.assert_allclose([t for t, _ in entries], moon.time)
    for frame, (_, name) in enumerate(entries):
        particles = meshio.read(out / name)
        np.testing.assert_allclose(
            particles.points, f[fields.BELL_POSITION.path][frame], atol=1e-12
        )
        np.testing.assert_allclose(
            particles.point_data["velocity"], f[fields.BELL_VELOCITY.path][frame], atol=1e-12
        )
        np.testing.assert_array_equal(particles.cells_dict["line"], pairs)
        np.testing.assert_array_equal(particles.cell_data["muscle"][0], muscle.astype(int))
        np.testing.assert_allclose(
            particles.cell_data["rest_length"][0],
            np.linalg.norm(rest[pairs[:, 1]] - rest[pairs[:, 0]], axis=1),
        )
        surface = meshio.read(out / f"bell_{frame:05d}.vtu")
        np.testing.assert_allclose(
            surface.points, f[fields.BELL_SURFACE_VERTICES.path][frame], atol=1e-6
        )
        fluid = meshio.read(out / f"fluid_{frame:05d}.vtu")
        alive = f[fields.FLUID_ALIVE.path][frame]
        np.testing.assert_allclose(
            fluid.points, f[fields.FLUID_POSITION.path][frame][alive], atol=1e-6
        )
    # The bell's particles are not among the fluid's.
    assert f[fields.FLUID_POSITION.path].shape[1] == len(f[fields.FLUID_KIND.path][:])
    first = f[fields.FLUID_POSITION.path][0].astype(float)
    gap = np.min(np.linalg.norm(first[:, None, :] - rest[None, ::7, :], axis=2))
    assert gap > 0.1 * 0.25


def test_fluid_particles_round_trip(tmp_path: Path) -> None:
    folder = tmp_path / "fluid"
    folder.mkdir()
    rng = np.random.default_rng(0)
    frames, count = 3, 50
    position = rng.uniform(0, 1, (frames, count, 2))
    alive = np.ones((frames, count), dtype=bool)
    alive[2, :5] = False
    with h5py.File(folder / "result.h5", "w") as f:
        f[fields.TIME.path] = np.arange(frames) * 0.1
        f[fields.FLUID_POSITION.path] = position
        f[fields.FLUID_VELOCITY.path] = rng.normal(size=(frames, count, 2))
        f[fields.FLUID_PRESSURE.path] = rng.uniform(0, 1e3, (frames, count))
        f[fields.FLUID_NUMBER_DENSITY.path] = rng.uniform(5, 7, (frames, count))
        f[fields.FLUID_ALIVE.path] = alive
        f[fields.FLUID_KIND.path] = (np.arange(count) % 3).astype(np.int8)
        f.attrs["scene"] = 'name = "block"\n'
        f.attrs["fps"] = 10.0
        f.attrs["frames_expected"] = frames
    with jellysim.open_result(folder) as result:
        paths = export(result, "vtk", tmp_path / "out")
    assert [p.name for p in paths] == ["fluid.pvd"]
    last = meshio.read(tmp_path / "out" / "fluid_00002.vtu")
    assert last.points.shape == (45, 3)  # dead particles left out
    np.testing.assert_allclose(last.points[:, :2], position[2, 5:])
    np.testing.assert_array_equal(last.point_data["particle"], np.arange(5, 50))
    with h5py.File(folder / "result.h5") as f:
        np.testing.assert_allclose(
            last.point_data["pressure"], f[fields.FLUID_PRESSURE.path][2, 5:]
        )
        np.testing.assert_allclose(
            last.point_data["velocity"][:, :2], f[fields.FLUID_VELOCITY.path][2, 5:]
        )
        np.testing.assert_allclose(
            last.point_data["number_density"], f[fields.FLUID_NUMBER_DENSITY.path][2, 5:]
        )
        np.testing.assert_array_equal(last.point_data["kind"], f[fields.FLUID_KIND.path][5:])


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (("--format", "stl"), "--format stl"),
        (("--format", "vtk", "--frames", "3:1"), "--frames"),
        (("--format", "vtk", "--every", "0"), "--every"),
    ],
)
def test_bad_export_input_exits_2(
    brown: jellysim.Result, args: tuple[str, ...], fragment: str
) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "jellysim", "export", str(brown.folder), *args],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 2
    assert fragment in done.stderr and len(done.stderr.strip().splitlines()) == 1
