"""``result.h5`` opened directly by other tools (issue 27): xarray (h5netcdf) and netCDF-C read its
HDF5 dimension scales as named dimensions with time as a coordinate, and ParaView's XDMF reader
(VTK's ``vtkXdmfReader``) reads the sidecar ``result.xdmf`` as a time series whose points and
velocities are result.h5's own numbers."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import h5py
import numpy as np
import pytest
import scenes

import jellysim
from jellysim import fields
from jellysim.export import export

xarray = pytest.importorskip("xarray")
vtk = pytest.importorskip("vtkmodules.vtkIOXdmf2")
from vtkmodules.util.numpy_support import vtk_to_numpy  # noqa: E402
from vtkmodules.vtkCommonDataModel import vtkCompositeDataSet  # noqa: E402
from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline  # noqa: E402


@pytest.fixture(scope="module")
def tentacles(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Tentacles of two groups (marginal threads, oral arms) on a kinematic bell."""
    folder = tmp_path_factory.mktemp("brown")
    jellysim.run(jellysim.load_scene("brown-jelly", {"duration": 0.1}), folder).close()
    return folder


@pytest.fixture(scope="module")
def soft_bell(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A mass-spring bell with two tentacles in its 3-D tank of water."""
    folder = tmp_path_factory.mktemp("moon")
    overrides = {**scenes.SMALL_MOON, "duration": 0.1, "fps": 10.0, "tentacles.count": 2}
    scene = jellysim.load_scene(scenes.one_table("moon-jelly"), overrides)
    jellysim.run(scene, folder).close()
    return folder


@pytest.fixture(scope="module")
def fluid_2d(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("dam")
    overrides = {"fluid.spacing": 0.01, "duration": 0.01, "fps": 200.0}
    jellysim.run(jellysim.load_scene("dam-break-2d", overrides), folder).close()
    return folder


def _tree(folder: Path) -> Any:
    return xarray.open_datatree(folder / "result.h5", engine="h5netcdf")


@pytest.mark.parametrize("name", ["tentacles", "soft_bell"])
def test_xarray_opens_result_h5_with_the_dimensions_of_to_xarray(
    name: str, request: pytest.FixtureRequest
) -> None:
    folder = request.getfixturevalue(name)
    with jellysim.open_result(folder) as r, _tree(folder) as tree:
        expected = r.to_xarray()
        np.testing.assert_array_equal(tree["time"].values, r.time)
        assert tree["time"].attrs["units"] == "s"
        assert list(tree["xyz"].values) == ["x", "y", "z"]
        seen = 0
        for node in tree.subtree:
            assert not any(str(d).startswith("phony_dim") for d in node.dims), node.path
            for variable in node.data_vars:
                path = f"{node.path.strip('/')}/{variable}"
                data = node[variable]
                mine = expected[path.replace("/", "_")]
                assert data.dims == mine.dims, path
                assert data.attrs["units"] == mine.attrs["units"], path
                if "time" in data.dims:
                    # time is the group's coordinate, inherited from the root
                    np.testing.assert_array_equal(data["time"].values, r.time)
                np.testing.assert_array_equal(data.values, mine.values)
                seen += 1
        assert seen == len(expected.data_vars)
    # One group opened alone: named dimensions too (its coordinates live at the root).
    with xarray.open_dataset(folder / "result.h5", engine="h5netcdf", group="tentacles") as ds:
        assert ds["position"].dims == ("time", "tentacle", "particle", "xyz")


def test_the_soft_bells_fluid_and_springs_are_named(soft_bell: Path) -> None:
    with _tree(soft_bell) as tree:
        assert tree["fluid/position"].dims == ("time", "fluid_particle", "dimension")
        assert tree["fluid/pressure"].attrs["units"] == "Pa"
        assert tree["bell/springs"].dims == ("spring", "end")
        assert tree["bell/velocity"].dims == ("time", "bell_particle", "xyz")
        assert tree["tentacles/position"].attrs["long_name"] == fields.TENTACLE_POSITION.doc


NETCDF_READ = """
import json, sys
import netCDF4
with netCDF4.Dataset(sys.argv[1]) as d:
    position = d["tentacles"].variables["position"]
    print(json.dumps({
        "dims": list(position.dimensions),
        "unlimited": d.dimensions["time"].isunlimited(),
        "time": [float(t) for t in d.variables["time"][:]],
        "fluid": list(d["fluid"].variables["position"].dimensions),
    }))
"""


def test_netcdf_c_reads_the_dimensions(soft_bell: Path) -> None:
    pytest.importorskip("netCDF4")
    # netCDF4 brings its own HDF5 library: read in a process of its own, away from h5py's.
    done = subprocess.run(
        [sys.executable, "-c", NETCDF_READ, str(soft_bell / "result.h5")],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    read = json.loads(done.stdout)
    assert read["dims"] == ["time", "tentacle", "particle", "xyz"]
    assert read["fluid"] == ["time", "fluid_particle", "dimension"]
    assert read["unlimited"]
    with jellysim.open_result(soft_bell) as r:
        assert read["time"] == r.time.tolist()


def _read_xdmf(path: Path) -> tuple[list[float], list[dict[str, dict[str, Any]]]]:
    """Every time step of an XDMF file as vtkXdmfReader (ParaView's) gives it: per part, its
    points, point and cell arrays, and its cells' types and sizes."""
    reader = vtk.vtkXdmfReader()
    reader.SetFileName(str(path))
    reader.UpdateInformation()
    listed = reader.GetOutputInformation(0).Get(vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    times = list(listed or ())
    steps = []
    for t in times:
        reader.UpdateTimeStep(t)
        output = reader.GetOutputDataObject(0)
        if output.IsA("vtkCompositeDataSet"):
            blocks = [
                (output.GetMetaData(b).Get(vtkCompositeDataSet.NAME()), output.GetBlock(b))
                for b in range(output.GetNumberOfBlocks())
            ]
        else:  # one part: the reader gives it alone, by the name of its collection
            (collection,) = ElementTree.parse(path).getroot().findall("Domain/Grid")
            blocks = [(collection.get("Name"), output)]
        parts = {}
        for name, block in blocks:
            points, cells = block.GetPointData(), block.GetCellData()
            parts[name] = {
                "points": vtk_to_numpy(block.GetPoints().GetData()).copy(),
                "point": {
                    points.GetArrayName(i): vtk_to_numpy(points.GetArray(i)).copy()
                    for i in range(points.GetNumberOfArrays())
                },
                "cell": {
                    cells.GetArrayName(i): vtk_to_numpy(cells.GetArray(i)).copy()
                    for i in range(cells.GetNumberOfArrays())
                },
                "cells": [
                    (block.GetCell(c).GetClassName(), block.GetCell(c).GetNumberOfPoints())
                    for c in range(block.GetNumberOfCells())
                ],
            }
        steps.append(parts)
    return times, steps


def _points(values: np.ndarray) -> np.ndarray:
    """Rows of (x, y, z): a 2-D fluid's (x, y) read as (x, y, 0), as VTK does."""
    flat = values.reshape(-1, values.shape[-1])
    return flat if flat.shape[1] == 3 else np.column_stack([flat, np.zeros(len(flat))])


def test_paraview_reads_the_tentacle_groups_and_the_kinematic_bell(tentacles: Path) -> None:
    times, steps = _read_xdmf(tentacles / "result.xdmf")
    with jellysim.open_result(tentacles) as r:
        assert times == r.time.tolist()
        for k, parts in enumerate(steps):
            assert list(parts) == [
                "tentacles_marginal",
                "tentacles_oral_arms",
                "rim",
                "margin",
                "bell",
            ]
            for number, group in enumerate(r.tentacle_groups):
                part = parts[f"tentacles_{group}"]
                x, v = r.group_positions(number, k), r.group_velocities(number, k)
                np.testing.assert_array_equal(part["points"], _points(x))
                np.testing.assert_array_equal(part["point"]["velocity"], _points(v))
                assert part["cells"] == [("vtkPolyLine", x.shape[1])] * x.shape[0]
            np.testing.assert_array_equal(parts["rim"]["points"], r.rim[k])
            np.testing.assert_array_equal(parts["rim"]["point"]["velocity"], r.rim_velocity[k])
            np.testing.assert_array_equal(parts["margin"]["points"], r.margin[k])
            margin_points = r.margin.shape[1]
            assert parts["margin"]["cells"] == [("vtkPolyLine", margin_points + 1)]  # closed
            bell = parts["bell"]
            np.testing.assert_array_equal(bell["points"], r.bell_surface_vertices[k])
            assert len(bell["cells"]) == len(r.bell_surface_faces)


def test_paraview_reads_the_soft_bell_and_its_water(soft_bell: Path) -> None:
    times, steps = _read_xdmf(soft_bell / "result.xdmf")
    with jellysim.open_result(soft_bell) as r:
        assert times == r.time.tolist()
        for k, parts in enumerate(steps):
            assert set(parts) == {"tentacles", "rim", "margin", "bell", "bell_particles", "fluid"}
            np.testing.assert_array_equal(
                parts["tentacles"]["points"], _points(r.tentacle_positions[k])
            )
            np.testing.assert_array_equal(
                parts["tentacles"]["point"]["velocity"], _points(r.tentacle_velocities[k])
            )
            body = parts["bell_particles"]
            np.testing.assert_array_equal(body["points"], r.bell_positions[k])
            np.testing.assert_array_equal(body["point"]["velocity"], r.bell_velocities[k])
            np.testing.assert_array_equal(body["cell"]["muscle"], r.bell_muscle.astype(np.uint8))
            assert len(body["cells"]) == len(r.bell_springs)
            water = parts["fluid"]
            np.testing.assert_array_equal(water["points"], r.fluid_positions[k])
            np.testing.assert_array_equal(water["point"]["velocity"], r.fluid_velocities[k])
            np.testing.assert_array_equal(water["point"]["pressure"], r.fluid_pressure[k])
            np.testing.assert_array_equal(water["point"]["alive"], r.fluid_alive[k])
            np.testing.assert_array_equal(water["point"]["kind"], r.fluid_kind)
        assert r.bell_muscle.any() and not r.bell_muscle.all()  # both values were compared


def test_paraview_reads_a_2d_fluid_as_points_in_the_plane(fluid_2d: Path) -> None:
    times, steps = _read_xdmf(fluid_2d / "result.xdmf")
    with jellysim.open_result(fluid_2d) as r:
        assert times == r.time.tolist()
        for k, parts in enumerate(steps):
            assert list(parts) == ["fluid"]
            np.testing.assert_array_equal(parts["fluid"]["points"], _points(r.fluid_positions[k]))
            np.testing.assert_array_equal(
                parts["fluid"]["point"]["velocity"], _points(r.fluid_velocities[k])
            )


def test_an_older_result_gets_its_sidecar_from_export(tentacles: Path, tmp_path: Path) -> None:
    """A result written before sidecars and tentacle groups: ``export --format xdmf`` writes
    the sidecar beside it; its tentacles are one group."""
    old = tmp_path / "old"
    old.mkdir()
    shutil.copy(tentacles / "result.h5", old / "result.h5")
    with h5py.File(old / "result.h5", "r+") as f:
        del f[fields.TENTACLE_GROUP.path], f[fields.TENTACLE_PARTICLES.path]
        del f.attrs["tentacle_groups"]
    done = subprocess.run(
        [sys.executable, "-m", "jellysim", "export", str(old), "--format", "XDMF"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == str(old / "result.xdmf")
    times, steps = _read_xdmf(old / "result.xdmf")
    with jellysim.open_result(old) as r:
        assert times == r.time.tolist()
        last = steps[-1]["tentacles"]
        np.testing.assert_array_equal(last["points"], _points(r.tentacle_positions[-1]))
        assert len(last["cells"]) == r.tentacle_positions.shape[1]


def test_export_elsewhere_names_the_result_from_there(tentacles: Path, tmp_path: Path) -> None:
    with jellysim.open_result(tentacles) as r:
        (path,) = export(r, "xdmf", tmp_path / "views", frames=(1, 3))
        times, steps = _read_xdmf(path)
        assert times == r.time[1:3].tolist()
        np.testing.assert_array_equal(steps[0]["margin"]["points"], r.margin[1])
    reference = os.path.relpath(tentacles / "result.h5", tmp_path / "views")
    assert f">{reference}:/tentacles/position<" in path.read_text()


def test_the_sidecar_follows_the_frames_as_they_are_written(tmp_path: Path) -> None:
    """Written at flushes, from the first frame on (none of no frame: vtkXdmfReader crashes on
    one of a single part, the 2-D fluid's): it always opens and lists frames the result holds,
    as a sidecar written from scratch would; at the end, every frame."""
    from jellysim.io.result import ResultWriter, frame_datasets
    from jellysim.io.xdmf import xdmf_text

    path = tmp_path / "result.h5"
    writer = ResultWriter(path, frame_datasets(2, 3, 4), {"fps": 10.0}, batch_frames=2)
    assert not (tmp_path / "result.xdmf").exists()
    rng = np.random.default_rng(1)
    checked = 0
    for k in range(5):
        writer.append(
            {
                "time": k / 10,
                "tentacles/position": rng.random((2, 3, 3)),
                "tentacles/velocity": rng.random((2, 3, 3)),
                "tentacles/constraint_error": 0.0,
                "tentacles/projection_iterations": 1,
                "bell/rim": rng.random((2, 3)),
                "bell/rim_velocity": rng.random((2, 3)),
                "bell/margin": rng.random((4, 3)),
            }
        )
        sidecar = tmp_path / "result.xdmf"
        assert sidecar.is_file() == (writer.frames > 0)
        listed = len(_read_xdmf(sidecar)[0]) if sidecar.is_file() else 0
        assert 0 < listed <= writer.frames or listed == writer.frames == 0
        if listed and listed == writer.frames:
            # Written at this flush: the writer formats only the frames added since its last
            # sidecar, and the text is the one written from scratch, the datasets' dimensions
            # as the file holds them now.
            assert sidecar.read_text() == xdmf_text(writer._file, "result.h5", range(listed))
            checked += 1
    assert checked >= 2  # at two flushes at least: the file grew between them
    writer.close()
    times, steps = _read_xdmf(tmp_path / "result.xdmf")
    with h5py.File(path, "r") as f:
        assert times == f["time"][()].tolist() == [0.0, 0.1, 0.2, 0.3, 0.4]
        assert (tmp_path / "result.xdmf").read_text() == xdmf_text(f, "result.h5", range(5))
        np.testing.assert_array_equal(
            steps[4]["tentacles"]["points"], f["tentacles/position"][4].reshape(-1, 3)
        )


def _export_cli(*arguments: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "jellysim", "export", *arguments],
        capture_output=True,
        text=True,
        timeout=120,
    )


def _refused(done: subprocess.CompletedProcess[str]) -> str:
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
    assert done.stdout == ""
    return lines[0]


def test_a_path_with_xml_characters_is_escaped(tentacles: Path, tmp_path: Path) -> None:
    """A result in 'R&D <1>' exported elsewhere: the sidecar names it escaped, parses as XML,
    and ParaView's reader finds the file through it."""
    run = tmp_path / "R&D <1>"
    run.mkdir()
    shutil.copy(tentacles / "result.h5", run / "result.h5")
    done = _export_cli(str(run), "--format", "xdmf", "--out", str(tmp_path / "views"))
    assert done.returncode == 0, done.stderr
    sidecar = tmp_path / "views" / "result.xdmf"
    assert done.stdout.strip() == str(sidecar)
    heavy = ElementTree.parse(sidecar).getroot().find("Domain/Grid/Grid/Geometry/DataItem")
    assert heavy is not None
    assert heavy[-1].text == "../R&D <1>/result.h5:/tentacles/position"
    assert "R&amp;D &lt;1&gt;" in sidecar.read_text()
    times, steps = _read_xdmf(sidecar)
    with jellysim.open_result(run) as r:
        assert times == r.time.tolist()
        np.testing.assert_array_equal(steps[-1]["margin"]["points"], r.margin[-1])


def test_a_path_xdmf_cannot_name_is_refused_in_one_line(tentacles: Path, tmp_path: Path) -> None:
    """XDMF 2's FILE:/DATASET form has no room for a ':' in FILE: a sidecar in 'views' that
    would name '../a:b/result.h5' is refused; one beside the result names it 'result.h5'."""
    run = tmp_path / "a:b"
    run.mkdir()
    shutil.copy(tentacles / "result.h5", run / "result.h5")
    line = _refused(_export_cli(str(run), "--format", "xdmf", "--out", str(tmp_path / "views")))
    assert "':'" in line and "../a:b/result.h5" in line
    assert not (tmp_path / "views" / "result.xdmf").exists()
    assert not list((tmp_path / "views").iterdir())
    done = _export_cli(str(run), "--format", "xdmf")
    assert done.returncode == 0, done.stderr
    times, steps = _read_xdmf(run / "result.xdmf")
    with jellysim.open_result(run) as r:
        assert times == r.time.tolist()
        np.testing.assert_array_equal(steps[-1]["rim"]["points"], r.rim[-1])


@pytest.mark.parametrize("selection", [["--frames", "1:3"], ["--every", "2"]])
def test_some_frames_never_replace_the_runs_own_sidecar(
    tentacles: Path, tmp_path: Path, selection: list[str]
) -> None:
    """The sidecar in DIR is the run's, of every frame: a selection of frames goes elsewhere."""
    run = tmp_path / "run"
    shutil.copytree(tentacles, run)
    whole = (run / "result.xdmf").read_bytes()
    for out in ([], ["--out", str(run)]):
        line = _refused(_export_cli(str(run), "--format", "xdmf", *selection, *out))
        assert "--out" in line and str(run / "result.xdmf") in line
        assert (run / "result.xdmf").read_bytes() == whole
    views = tmp_path / "views"
    done = _export_cli(str(run), "--format", "xdmf", *selection, "--out", str(views))
    assert done.returncode == 0, done.stderr
    with jellysim.open_result(run) as r:
        expected = r.time[1:3] if "--frames" in selection else r.time[::2]
        assert _read_xdmf(views / "result.xdmf")[0] == expected.tolist()
    # Every frame, into DIR itself: the run's sidecar written again, the same.
    assert _export_cli(str(run), "--format", "xdmf").returncode == 0
    assert (run / "result.xdmf").read_bytes() == whole


def test_sidecar_writers_never_share_a_temporary_file(
    tentacles: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each write of a sidecar has a temporary file of its own beside it (a run and an export
    of the same folder at once must not write into one file), left nowhere after."""
    from jellysim.io import xdmf

    run = tmp_path / "run"
    shutil.copytree(tentacles, run)
    stale = run / "result.xdmf.tmp"  # the one name every writer used
    stale.write_text("another writer's")
    renamed: list[Path] = []
    replace = os.replace

    def recording(source: Any, target: Any) -> None:
        renamed.append(Path(source))
        replace(source, target)

    monkeypatch.setattr(xdmf.os, "replace", recording)
    with jellysim.open_result(run) as r:
        for _ in range(2):
            export(r, "xdmf")
            xdmf.write_xdmf(r.file, r.path, run / xdmf.XDMF_FILE, range(r.frames))
    assert len(set(renamed)) == 4
    assert all(path.parent == run and path != stale for path in renamed)
    assert stale.read_text() == "another writer's"
    assert sorted(p.name for p in run.iterdir() if p.name.endswith(".tmp")) == [stale.name]


class _PathLike:
    """An ``os.PathLike`` that is not a ``pathlib.Path``."""

    def __init__(self, path: Path) -> None:
        self._path = str(path)

    def __fspath__(self) -> str:
        return self._path


@pytest.mark.parametrize("kind", [str, _PathLike])
@pytest.mark.parametrize("fmt", ["vtk", "obj", "ply", "usd", "gltf", "xdmf"])
def test_export_takes_the_folder_as_str_or_pathlike(
    tentacles: Path, tmp_path: Path, fmt: str, kind: Any
) -> None:
    if fmt == "usd":
        pytest.importorskip("pxr")
    out = tmp_path / "exported"
    with jellysim.open_result(tentacles) as r:
        paths = export(r, fmt, kind(out), frames=(0, 2))
    assert paths
    for path in paths:
        assert isinstance(path, Path) and path.is_file() and out in path.parents
