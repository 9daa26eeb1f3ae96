"""``Result.to_xarray()`` (issue 27): a result as an xarray Dataset with named dimensions, time
as a coordinate and units as attributes, the same numbers as the result holds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scenes
import xarray

import jellysim
from jellysim import fields


@pytest.fixture(scope="module")
def brown(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("brown")
    jellysim.run(jellysim.load_scene("brown-jelly", {"duration": 0.2}), folder).close()
    return folder


def test_a_result_as_an_xarray_dataset(brown: Path) -> None:
    with jellysim.open_result(brown) as r:
        ds = r.to_xarray()
        assert isinstance(ds, xarray.Dataset)
        position = ds["tentacles_position"]
        assert position.dims == ("time", "tentacle", "particle", "xyz")
        assert position.attrs["units"] == "m"
        np.testing.assert_array_equal(ds["time"].values, r.time)
        assert ds["time"].attrs["units"] == "s"
        np.testing.assert_array_equal(position.values, r.tentacle_positions)
        tips = position.sel(xyz="z").isel(particle=-1)
        np.testing.assert_array_equal(tips.values, r.tentacle_positions[:, :, -1, 2])
        assert ds["bell_surface_faces"].dims == ("triangle", "corner")
        assert ds.attrs["tentacle_groups"] == "marginal, oral_arms"
        # Some frames only, as Result.read takes them.
        two = r.to_xarray(frames=slice(1, 3))
        np.testing.assert_array_equal(two["time"].values, r.time[1:3])
        assert two["tentacles_position"].shape[0] == 2
        one = r.to_xarray(frames=4)
        assert one.sizes["time"] == 1


def test_the_fluid_and_the_soft_bell_too(tmp_path: Path) -> None:
    overrides = {**scenes.SMALL_MOON, "duration": 0.1, "fps": 10.0, "tentacles.count": 2}
    scene = jellysim.load_scene(scenes.one_table("moon-jelly"), overrides)
    with jellysim.run(scene, tmp_path) as r:
        ds = r.to_xarray()
        assert ds["fluid_position"].dims == ("time", "fluid_particle", "dimension")
        assert ds["fluid_pressure"].attrs["units"] == "Pa"
        assert ds["bell_springs"].dims == ("spring", "end")
        np.testing.assert_array_equal(ds["fluid_pressure"].values, r.read(fields.FLUID_PRESSURE))


def test_without_xarray_one_sentence_says_what_to_install(
    brown: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(__import__("sys").modules, "xarray", None)  # import xarray fails
    with jellysim.open_result(brown) as r, pytest.raises(jellysim.InputError, match="pip install"):
        r.to_xarray()


def test_one_frame_by_a_numpy_integer_keeps_its_time_axis(brown: Path) -> None:
    with jellysim.open_result(brown) as r:
        one = r.to_xarray(frames=np.int64(4))
        assert one.sizes["time"] == 1
        np.testing.assert_array_equal(one["time"].values, r.time[4:5])
