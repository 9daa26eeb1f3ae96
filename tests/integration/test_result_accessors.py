"""``Result``'s typed accessors read each dataset of the layout (jellysim.fields) as stored: the
frames written, the dtype and shape the field declares, the units the file carries, and the same
values as h5py; a dataset a result lacks raises InputError naming it."""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from regression.compare import run_case

import jellysim
from jellysim import fields
from jellysim.errors import InputError
from jellysim.io.result import Result

# Every field and the Result property that reads it.
ACCESSORS: dict[fields.Field, str] = {
    fields.TIME: "time",
    fields.TENTACLE_POSITION: "tentacle_positions",
    fields.TENTACLE_VELOCITY: "tentacle_velocities",
    fields.TENTACLE_GROUP: "tentacle_group",
    fields.TENTACLE_PARTICLES: "tentacle_particles",
    fields.TENTACLE_CONSTRAINT_ERROR: "tentacle_constraint_error",
    fields.TENTACLE_PROJECTION_ITERATIONS: "tentacle_projection_iterations",
    fields.BELL_RIM: "rim",
    fields.BELL_RIM_VELOCITY: "rim_velocity",
    fields.BELL_MARGIN: "margin",
    fields.BELL_POSITION: "bell_positions",
    fields.BELL_VELOCITY: "bell_velocities",
    fields.BELL_SURFACE_VERTICES: "bell_surface_vertices",
    fields.BELL_CENTRE: "bell_centre",
    fields.BELL_CONTRACTION: "bell_contraction",
    fields.BELL_ACTIVATION: "bell_activation",
    fields.BELL_SURFACE_FACES: "bell_surface_faces",
    fields.BELL_SPRINGS: "bell_springs",
    fields.BELL_MUSCLE: "bell_muscle",
    fields.BELL_REST_POSITION: "bell_rest_positions",
    fields.FLUID_POSITION: "fluid_positions",
    fields.FLUID_VELOCITY: "fluid_velocities",
    fields.FLUID_PRESSURE: "fluid_pressure",
    fields.FLUID_NUMBER_DENSITY: "fluid_number_density",
    fields.FLUID_ALIVE: "fluid_alive",
    fields.FLUID_KIND: "fluid_kind",
    fields.SOLVER_ITERATIONS: "solver_iterations",
    fields.SOLVER_RESIDUAL: "solver_residual",
    fields.SOLVER_STEPS: "solver_steps",
    fields.PROBE_HEIGHT: "probe_heights",
    fields.PROBE_PRESSURE: "probe_pressures",
}

# Reference cases (tests/regression/cases.py) covering every writer: tentacles driven by forced
# roots (no bell body), a kinematic bell, a 2-D MPS fluid, a mass-spring bell in a 3-D tank, a
# 3-D tank with probes.
CASES = ("forced-tentacles", "brown-jelly", "dam-break-2d", "moon-jelly", "spheric-test2")

# Datasets each case writes (per the writers); the rest are absent.
WRITTEN = {
    "forced-tentacles": {
        fields.TIME,
        fields.TENTACLE_POSITION,
        fields.TENTACLE_VELOCITY,
        fields.TENTACLE_GROUP,
        fields.TENTACLE_PARTICLES,
        fields.TENTACLE_CONSTRAINT_ERROR,
        fields.TENTACLE_PROJECTION_ITERATIONS,
        fields.BELL_RIM,
        fields.BELL_RIM_VELOCITY,
        fields.BELL_MARGIN,
    },
    "dam-break-2d": {
        fields.TIME,
        fields.FLUID_POSITION,
        fields.FLUID_VELOCITY,
        fields.FLUID_PRESSURE,
        fields.FLUID_NUMBER_DENSITY,
        fields.FLUID_ALIVE,
        fields.FLUID_KIND,
        fields.SOLVER_ITERATIONS,
        fields.SOLVER_RESIDUAL,
        fields.SOLVER_STEPS,
    },
}
WRITTEN["brown-jelly"] = WRITTEN["forced-tentacles"] | {
    fields.BELL_POSITION,
    fields.BELL_SURFACE_VERTICES,
    fields.BELL_SURFACE_FACES,
    fields.BELL_CENTRE,
    fields.BELL_CONTRACTION,
}
WRITTEN["spheric-test2"] = WRITTEN["dam-break-2d"] | {fields.PROBE_HEIGHT, fields.PROBE_PRESSURE}
WRITTEN["moon-jelly"] = (
    WRITTEN["forced-tentacles"]
    | WRITTEN["dam-break-2d"]
    | {
        fields.BELL_POSITION,
        fields.BELL_VELOCITY,
        fields.BELL_SURFACE_VERTICES,
        fields.BELL_SURFACE_FACES,
        fields.BELL_CENTRE,
        fields.BELL_CONTRACTION,
        fields.BELL_ACTIVATION,
        fields.BELL_SPRINGS,
        fields.BELL_MUSCLE,
        fields.BELL_REST_POSITION,
    }
)


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("accessors")
    return {name: run_case(name, folder / name) for name in CASES}


def test_every_field_has_an_accessor() -> None:
    assert set(ACCESSORS) == set(fields.FIELDS)
    assert set().union(*WRITTEN.values()) == set(fields.FIELDS)  # the cases write them all
    assert len(set(ACCESSORS.values())) == len(fields.FIELDS)
    for name in ACCESSORS.values():
        assert isinstance(getattr(Result, name), property), name


@pytest.mark.parametrize("case", CASES)
def test_accessors_read_what_h5py_reads(case: str, results: dict[str, Path]) -> None:
    sizes: dict[str, int] = {}
    with jellysim.open_result(results[case]) as r, h5py.File(results[case], "r") as raw:
        frames = r.frames
        assert frames == raw[fields.TIME.path].shape[0] == r.expected_frames >= 2
        present = {field for field in fields.FIELDS if r.has(field)}
        assert present == WRITTEN[case]
        for field in present:
            value = getattr(r, ACCESSORS[field])
            stored = raw[field.path]
            assert isinstance(value, np.ndarray)
            assert value.dtype == stored.dtype, field.path
            np.testing.assert_array_equal(value, stored[()], err_msg=field.path)
            assert stored.attrs["units"] == field.units, field.path
            shape = value.shape[1:] if field.per_frame else value.shape
            if field.per_frame:
                assert value.shape[0] == frames, field.path
            assert len(shape) == len(field.axes), field.path
            for axis, size in zip(field.axes, shape, strict=True):
                expected = sizes.setdefault(axis, size) if isinstance(axis, str) else axis
                assert size == expected, f"{field.path}: axis {axis} is {size}, not {expected}"
        # Stored as declared, but where a writer says otherwise: the kinematic bell's position
        # is its float32 surface (a link), the mass-spring bell's tank is float32.
        for field in present:
            expected = field.dtype
            if case == "brown-jelly" and field is fields.BELL_POSITION:
                expected = np.float32
            if case == "moon-jelly" and field.path.startswith("fluid/") and expected == np.float64:
                expected = np.float32
            assert raw[field.path].dtype == expected, field.path


@pytest.mark.parametrize("case", CASES)
def test_a_missing_dataset_raises_input_error(case: str, results: dict[str, Path]) -> None:
    with jellysim.open_result(results[case]) as r:
        missing = [field for field in fields.FIELDS if field not in WRITTEN[case]]
        if case == "moon-jelly":  # everything but the fluid-only scenes' probes
            assert missing == [fields.PROBE_HEIGHT, fields.PROBE_PRESSURE]
        for field in missing:
            assert not r.has(field)
            with pytest.raises(InputError, match=field.path):
                getattr(r, ACCESSORS[field])
            with pytest.raises(InputError, match=field.path):
                r.dataset(field)


def test_bell_values(results: dict[str, Path]) -> None:
    with jellysim.open_result(results["moon-jelly"]) as soft:
        positions = soft.bell_positions
        assert positions.dtype == np.float64
        np.testing.assert_allclose(soft.bell_centre, positions.mean(axis=1), rtol=0, atol=1e-15)
        np.testing.assert_array_equal(positions[0], soft.bell_rest_positions)
        springs, muscle = soft.bell_springs, soft.bell_muscle
        assert springs.shape == (int(soft.file.attrs["bell_springs"]), 2)
        assert springs.min() >= 0 and springs.max() < positions.shape[1]
        assert int(muscle.sum()) == int(soft.file.attrs["muscle_springs"]) > 0
        activation = soft.bell_activation
        assert np.all((activation >= 0.0) & (activation <= 1.0))
        assert soft.bell_surface_faces.max() < soft.bell_surface_vertices.shape[1]
        kinds = soft.fluid_kind
        assert set(np.unique(kinds)) == {0, 1, 2}
        assert int(np.sum(kinds == 0)) == int(soft.file.attrs["fluid_particles"])
    with jellysim.open_result(results["brown-jelly"]) as kinematic:
        # The kinematic bell's position is a hard link to its surface vertices.
        np.testing.assert_array_equal(kinematic.bell_positions, kinematic.bell_surface_vertices)
        assert kinematic.bell_positions.dtype == np.float32
        contraction = kinematic.bell_contraction
        assert np.all((contraction >= 0.0) & (contraction < 1.0))
        with pytest.raises(InputError, match="bell.model = 'kinematic'"):
            kinematic.read(fields.BELL_VELOCITY)


def test_fluid_and_solver_values(results: dict[str, Path]) -> None:
    with jellysim.open_result(results["dam-break-2d"]) as r:
        positions = r.fluid_positions
        assert positions.dtype == np.float64 and positions.shape[2] == 2
        assert r.fluid_alive.dtype == np.bool_ and r.fluid_alive[0].all()
        fluid = r.fluid_kind == 0
        assert np.all(r.fluid_number_density[-1][fluid] > 0.0)
        assert np.all(r.fluid_pressure[-1][fluid] >= 0.0)
        assert np.all(r.solver_steps[1:] >= 1) and np.all(r.solver_iterations[1:] >= 1)
        assert np.all(np.isfinite(r.solver_residual))


def test_read_picks_frames(results: dict[str, Path]) -> None:
    with jellysim.open_result(results["forced-tentacles"]) as r:
        whole = r.tentacle_positions
        count = r.frames
        np.testing.assert_array_equal(r.read(fields.TENTACLE_POSITION, 1), whole[1])
        np.testing.assert_array_equal(r.read(fields.TENTACLE_POSITION, -1), whole[-1])
        np.testing.assert_array_equal(r.read(fields.TENTACLE_POSITION, slice(1, None)), whole[1:])
        np.testing.assert_array_equal(
            r.read(fields.TENTACLE_POSITION, [0, count - 1]), whole[[0, -1]]
        )
        with pytest.raises(IndexError):
            r.read(fields.TENTACLE_POSITION, count)
        with pytest.raises(ValueError, match="run backwards"):
            r.read(fields.TENTACLE_POSITION, slice(None, None, -1))
    with jellysim.open_result(results["brown-jelly"]) as r:
        with pytest.raises(ValueError, match="written once"):
            r.read(fields.BELL_SURFACE_FACES, 0)


def test_rows_past_the_frames_written_are_not_read(
    results: dict[str, Path], tmp_path: Path
) -> None:
    """A run killed mid-batch leaves per-frame datasets longer than ``time``: readers stop at
    the frames written."""
    path = tmp_path / "result.h5"
    shutil.copyfile(results["brown-jelly"], path)
    with h5py.File(path, "a") as f:
        for field in (fields.TENTACLE_POSITION, fields.BELL_SURFACE_VERTICES):
            ds = f[field.path]
            ds.resize(ds.shape[0] + 1, axis=0)
            ds[-1] = np.nan
        frames = f[fields.TIME.path].shape[0]
    with jellysim.open_result(tmp_path) as r:
        assert r.frames == frames
        assert r.tentacle_positions.shape[0] == frames
        assert r.bell_surface_vertices.shape[0] == frames
        assert np.all(np.isfinite(r.tentacle_positions))
        assert r.dataset(fields.TENTACLE_POSITION).shape[0] == frames + 1
