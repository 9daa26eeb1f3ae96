"""brown-jelly with its kinematic bell, end to end: result.h5's bell datasets (DESIGN §3) and
tentacles that hang from, follow and stay out of the bell."""

from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

import jellysim
from jellysim import fields
from jellysim.bell import make_root_driver
from jellysim.io.plots import jetting_and_relaxation, phase_frames


@pytest.fixture(scope="module")
def brown(tmp_path_factory: pytest.TempPathFactory) -> jellysim.Result:
    return jellysim.run(
        "brown-jelly", tmp_path_factory.mktemp("brown"), overrides={"duration": 3.0}
    )


def test_bell_datasets_have_the_design_shapes_and_units(brown: jellysim.Result) -> None:
    f = brown.file
    frames = brown.frames
    driver = make_root_driver(brown.scene)
    vertices = f[fields.BELL_SURFACE_VERTICES.path]
    assert vertices.shape == (frames, driver.surface(0.0).shape[0], 3)
    assert f[fields.BELL_SURFACE_FACES.path].shape == (driver.faces.shape[0], 3)
    assert f[fields.BELL_SURFACE_FACES.path].dtype.kind == "i"
    assert int(f[fields.BELL_SURFACE_FACES.path][:].max()) == vertices.shape[1] - 1
    assert (
        f[fields.BELL_POSITION.path].id == vertices.id
    )  # the same data, stored once (a hard link)
    assert f[fields.BELL_MARGIN.path].shape == (frames, driver.sectors, 3)
    assert f[fields.BELL_CENTRE.path].shape == (frames, 3)
    assert f[fields.BELL_CONTRACTION.path].shape == (frames,)
    for field in (
        fields.BELL_SURFACE_VERTICES,
        fields.BELL_SURFACE_FACES,
        fields.BELL_MARGIN,
        fields.BELL_CENTRE,
        fields.BELL_CONTRACTION,
        fields.BELL_RIM,
    ):
        assert f[field.path].attrs["units"] == field.units, field.path
    assert f.attrs["bell_model"] == "kinematic"


def test_stored_bell_is_the_bells_shape_at_each_frame(brown: jellysim.Result) -> None:
    driver = make_root_driver(brown.scene)
    time = brown.time
    for frame in (0, 9, 31, len(time) - 1):
        np.testing.assert_allclose(
            brown.file[fields.BELL_SURFACE_VERTICES.path][frame],
            driver.surface(time[frame]),
            atol=1e-6,
        )
        np.testing.assert_allclose(brown.margin[frame], driver.margin(time[frame]), atol=1e-15)
    q, _, z, _ = driver.motion(time)
    np.testing.assert_allclose(brown.file[fields.BELL_CONTRACTION.path][:], q, atol=1e-15)
    np.testing.assert_allclose(brown.file[fields.BELL_CENTRE.path][:, 2], z, atol=1e-15)


def test_roots_ride_the_pulsing_swimming_margin(brown: jellysim.Result) -> None:
    positions, rim = brown.tentacle_positions, brown.rim
    np.testing.assert_allclose(positions[:, :, 0], rim, atol=1e-12)
    # The bell swam its mean speed for the whole run (three whole cycles).
    centre = brown.file[fields.BELL_CENTRE.path][:, 2]
    swim_speed = brown.scene.bell.swim_speed
    assert centre[-1] - centre[0] == pytest.approx(swim_speed * 3.0, rel=1e-9)
    # The tentacles came along, trailing behind the margin; they start in their curled rest
    # shape (issue 25) and the flow draws them out.
    tips = positions[:, :, -1, 2] - centre[:, None]
    assert np.all(tips < -0.05)
    assert tips[-1].mean() < tips[0].mean() - 0.1


@pytest.mark.parametrize(
    "overrides",
    [{}, {"flow.speed": 0.0, "bell.swim_speed": 0.0, "flow.noise": 0.0}],
    ids=["preset", "still-water-no-flow"],
)
def test_tentacles_never_enter_the_bell(tmp_path: Path, overrides: dict) -> None:
    # No contact model (the paper has none): this guards the regime of the presets, where the
    # clamp and the trailing flow keep every particle below the margin.
    result = jellysim.run("brown-jelly", tmp_path, overrides={"duration": 3.0, **overrides})
    driver = make_root_driver(result.scene)
    positions, time = result.tentacle_positions, result.time
    inside = [driver.inside(positions[f, :, 1:], time[f]).sum() for f in range(len(time))]
    assert sum(inside) == 0


def test_a_bell_without_contraction_holds_still_and_its_tentacles_hang(tmp_path: Path) -> None:
    overrides = {
        "duration": 1.0,
        "bell.contraction": 0.0,
        "bell.swim_speed": 0.0,
        "flow.speed": 0.0,
        "flow.noise": 0.0,
        # Straight at rest: the preset's curl would coil the slack tentacles (issue 25).
        "tentacles.rest_curvature": 0.0,
        "tentacles.rest_curvature_tip": 0.0,
        "tentacles.oral_arms.rest_curvature": 0.0,  # the arms set their own curl
        "tentacles.oral_arms.rest_curvature_tip": 0.0,
        "tentacles.oral_arms.rest_torsion": 0.0,
    }
    result = jellysim.run("brown-jelly", tmp_path, overrides=overrides)
    positions = result.tentacle_positions
    np.testing.assert_allclose(
        positions, np.broadcast_to(positions[:1], positions.shape), atol=1e-9
    )
    # Both groups hang straight down from their roots (the margin, the mouth: z = 0).
    for group in result.scene.tentacle_groups:
        own = result.group_positions(group.name)
        spacing = group.tentacles.spacing
        hanging = np.broadcast_to(-spacing * np.arange(own.shape[2]), own.shape[1:3])
        np.testing.assert_allclose(own[-1, :, :, 2], hanging, atol=1e-9)
    vertices = result.file[fields.BELL_SURFACE_VERTICES.path][:]
    np.testing.assert_array_equal(vertices, np.broadcast_to(vertices[:1], vertices.shape))


def test_fig9_picks_full_contraction_and_late_relaxation(brown: jellysim.Result) -> None:
    jetting, relaxing = phase_frames(brown)
    contraction = brown.file[fields.BELL_CONTRACTION.path][:]
    assert contraction[jetting] == pytest.approx(brown.scene.bell.contraction, rel=0.01)
    assert contraction[relaxing] < 0.01 * brown.scene.bell.contraction
    assert brown.time[jetting] >= brown.time[-1] - brown.scene.bell.period - 1e-9  # last cycle
    path = jetting_and_relaxation(brown, brown.folder / "fig9.png")
    pixels = matplotlib.image.imread(path)
    assert pixels.shape[0] > 400 and pixels[..., :3].std() > 0.05  # drawn, not blank
