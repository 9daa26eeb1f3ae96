"""``jellysim export --format usd``: one stage read back with usd-core, compared with result.h5
at several time codes, and passing USD's own validators (UsdValidation, all registered)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import jellysim
from jellysim.export import export
from jellysim.interpolation import interpolate_result

pxr = pytest.importorskip("pxr", reason="usd-core is a test dependency (pip install -e .[test])")
from pxr import Usd, UsdGeom, UsdValidation  # noqa: E402


@pytest.fixture(scope="module")
def stage_and_result(tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.mktemp("brown")
    result = jellysim.run("brown-jelly", folder, overrides={"duration": 0.4, "fps": 10.0})
    (path,) = export(result, "usd", folder / "usd", interpolation=2)
    return Usd.Stage.Open(str(path)), result


def test_stage_metadata(stage_and_result) -> None:
    stage, result = stage_and_result
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert stage.GetDefaultPrim().GetPath() == "/Jellyfish"
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, result.frames - 1)
    assert stage.GetTimeCodesPerSecond() == 10.0


def test_bell_and_tentacles_match_the_result(stage_and_result) -> None:
    stage, result = stage_and_result
    bell = UsdGeom.Mesh(stage.GetPrimAtPath("/Jellyfish/Bell"))
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Jellyfish/Tentacles"))
    faces = result.file["bell/surface_faces"][:]
    np.testing.assert_array_equal(np.array(bell.GetFaceVertexIndicesAttr().Get()), faces.ravel())
    drawn = interpolate_result(result, 2)
    assert list(curves.GetCurveVertexCountsAttr().Get()) == [60] * 12
    widths = np.array(curves.GetWidthsAttr().Get()).reshape(12, 60)
    assert np.all(np.diff(widths, axis=1) < 0)  # tapered from root to tip
    for frame in (0, 2, result.frames - 1):
        points = np.array(bell.GetPointsAttr().Get(frame))
        np.testing.assert_allclose(points, result.file["bell/surface_vertices"][frame], atol=1e-6)
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
        f["time"] = np.array([0.0, 0.1])
        f["fluid/position"] = position
        f["fluid/alive"] = alive
        f["fluid/kind"] = np.zeros(20, dtype=np.int8)
        f.attrs["scene"] = 'name = "b"\n'
        f.attrs["fps"] = 10.0
        f.attrs["frames_expected"] = 2
        f.attrs["particle_spacing"] = 0.01
    with jellysim.open_result(folder) as result:
        (path,) = export(result, "usd", tmp_path / "usd")
    stage = Usd.Stage.Open(str(path))
    points = UsdGeom.Points(stage.GetPrimAtPath("/Jellyfish/Fluid"))
    last = np.array(points.GetPointsAttr().Get(1))
    assert last.shape == (17, 3)  # dead particles left out
    np.testing.assert_allclose(last[:, [0, 2]], position[1, 3:], atol=1e-6)  # 2-D: (x, 0, y)
    assert np.all(last[:, 1] == 0.0)
    assert list(points.GetWidthsAttr().Get()) == [pytest.approx(0.01)]
