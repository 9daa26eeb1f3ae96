"""result.h5 follows the layout of DESIGN §3: shapes, units, attributes, frame times and the
geometric invariants the readers rely on (roots on the rim, rim on the margin, inextensible
chains), and runs are reproducible from the seed."""

from __future__ import annotations

import tomllib
from pathlib import Path

import h5py
import numpy as np
import pytest

import jellysim
from jellysim import fields

# Short runs of the forced-tentacles preset (bell.model = "none", forced radial roots).
BASE = {
    "duration": 1.01,  # duration * fps = 20.2: F = round(20.2) + 1 = 21
    "fps": 20.0,
    "tentacles.count": 3,
    "tentacles.particles": 20,
}

# DESIGN §3: per-frame datasets, their trailing shape (names stand for sizes) and units.
PER_FRAME = {
    fields.TIME.path: ((), "s"),
    fields.TENTACLE_POSITION.path: (("T", "P", 3), "m"),
    fields.TENTACLE_VELOCITY.path: (("T", "P", 3), "m/s"),
    fields.BELL_RIM.path: (("T", 3), "m"),
    fields.BELL_RIM_VELOCITY.path: (("T", 3), "m/s"),
    fields.BELL_MARGIN.path: (("R", 3), "m"),
    fields.BELL_POSITION.path: (("B", 3), "m"),
    fields.BELL_SURFACE_VERTICES.path: (("V", 3), "m"),
    fields.FLUID_POSITION.path: (("N", "D"), "m"),
    fields.FLUID_VELOCITY.path: (("N", "D"), "m/s"),
    fields.FLUID_PRESSURE.path: (("N",), "Pa"),
    fields.FLUID_NUMBER_DENSITY.path: (("N",), None),
    fields.FLUID_ALIVE.path: (("N",), None),
    fields.SOLVER_ITERATIONS.path: ((), None),
}


def _run(folder: Path, overrides: dict[str, object]) -> jellysim.Scene:
    scene = jellysim.load_scene("forced-tentacles", {**BASE, **overrides})
    jellysim.run(scene, folder, force=True).close()
    return scene


def _datasets(f: h5py.File) -> dict[str, np.ndarray]:
    found: dict[str, np.ndarray] = {}

    def visit(name: str, obj: object) -> None:
        if isinstance(obj, h5py.Dataset):
            found[name] = obj[()]

    f.visititems(visit)
    return found


@pytest.fixture(scope="module")
def brown(tmp_path_factory: pytest.TempPathFactory) -> tuple[jellysim.Scene, Path]:
    folder = tmp_path_factory.mktemp("layout")
    return _run(folder, {}), folder


def test_per_frame_datasets_have_the_design_shapes(brown: tuple[jellysim.Scene, Path]) -> None:
    scene, folder = brown
    t = scene.tentacles
    frames = round(scene.duration * scene.fps) + 1
    assert frames == 21 == scene.frame_count
    with jellysim.open_result(folder) as r:
        f = r.file
        for name in (
            fields.TIME.path,
            fields.TENTACLE_POSITION.path,
            fields.TENTACLE_VELOCITY.path,
            fields.BELL_RIM.path,
            fields.BELL_RIM_VELOCITY.path,
            fields.BELL_MARGIN.path,
        ):
            assert name in f, f"{name} missing from result.h5"
        assert f[fields.TIME.path].shape == (frames,)
        assert f[fields.TENTACLE_POSITION.path].shape == (frames, t.count, t.particles, 3)
        assert f[fields.TENTACLE_VELOCITY.path].shape == (frames, t.count, t.particles, 3)
        assert f[fields.BELL_RIM.path].shape == (frames, t.count, 3)
        assert f[fields.BELL_RIM_VELOCITY.path].shape == (frames, t.count, 3)
        margin = f[fields.BELL_MARGIN.path]
        assert margin.ndim == 3 and margin.shape[0] == frames and margin.shape[2] == 3
        assert margin.shape[1] >= t.count
        sizes = {"T": t.count, "P": t.particles}
        for name, (trailing, _) in PER_FRAME.items():
            if name not in f:
                continue
            shape = f[name].shape
            assert shape[0] == frames, f"{name}: {shape[0]} frames, expected {frames}"
            assert len(shape) == 1 + len(trailing), f"{name}: shape {shape}"
            for size, want in zip(shape[1:], trailing, strict=True):
                expected = sizes.setdefault(want, size) if isinstance(want, str) else want
                assert size == expected, f"{name}: shape {shape}, expected {trailing}"
        if fields.BELL_SURFACE_FACES.path in f:
            faces = f[fields.BELL_SURFACE_FACES.path][()]
            assert faces.ndim == 2 and faces.shape[1] == 3
            if fields.BELL_SURFACE_VERTICES.path in f:
                assert faces.min() >= 0
                assert faces.max() < f[fields.BELL_SURFACE_VERTICES.path].shape[1]


def _is_dimension_only(dataset: h5py.Dataset) -> bool:
    """A netCDF dimension's scale that holds no physical values (docs/results.md): one marked
    "This is a netCDF dimension but not a netCDF variable", or the text labels of ``xyz``."""
    if dataset.attrs.get("CLASS") != b"DIMENSION_SCALE":
        return False
    name = dataset.attrs.get("NAME", b"")
    return name.startswith(b"This is a netCDF dimension") or dataset.dtype.kind in "SOU"


def test_every_dataset_carries_its_units(brown: tuple[jellysim.Scene, Path]) -> None:
    _, folder = brown
    with jellysim.open_result(folder) as r:
        names = [name for name in _datasets(r.file) if not _is_dimension_only(r.file[name])]
        assert names and "time" in names
        for name in names:
            units = r.file[name].attrs.get("units")
            assert units is not None, f"{name} has no 'units' attribute"
            units = units.decode() if isinstance(units, bytes) else str(units)
            assert units.strip(), f"{name} has an empty 'units' attribute"
            expected = PER_FRAME.get(name, (None, None))[1]
            if expected is not None:
                assert units == expected, f"{name}: units {units!r}, expected {expected!r}"


def test_root_attributes(brown: tuple[jellysim.Scene, Path]) -> None:
    scene, folder = brown
    with jellysim.open_result(folder) as r:
        attrs = r.file.attrs
        text = str(attrs["scene"])
        assert jellysim.load_scene(tomllib.loads(text)) == scene
        assert r.scene == scene
        assert str(attrs["version"]) == jellysim.__version__
        assert int(attrs["seed"]) == scene.seed


def test_frame_times(brown: tuple[jellysim.Scene, Path]) -> None:
    scene, folder = brown
    with jellysim.open_result(folder) as r:
        time = r.time
    assert time.shape == (scene.frame_count,)
    assert time[0] == 0.0
    np.testing.assert_allclose(np.diff(time), 1.0 / scene.fps, rtol=1e-12)
    np.testing.assert_allclose(time, np.arange(scene.frame_count) / scene.fps, rtol=1e-12)


def test_all_values_finite(brown: tuple[jellysim.Scene, Path]) -> None:
    _, folder = brown
    with jellysim.open_result(folder) as r:
        for name, data in _datasets(r.file).items():
            if np.issubdtype(data.dtype, np.floating):
                assert np.all(np.isfinite(data)), f"{name} holds non-finite values"


def test_root_particle_follows_the_rim(brown: tuple[jellysim.Scene, Path]) -> None:
    _, folder = brown
    with jellysim.open_result(folder) as r:
        positions, velocities = r.tentacle_positions, r.tentacle_velocities
        rim, rim_velocity = r.rim, r.rim_velocity
    np.testing.assert_allclose(positions[:, :, 0], rim, rtol=0, atol=1e-12)
    np.testing.assert_allclose(velocities[:, :, 0], rim_velocity, rtol=0, atol=1e-12)


def test_rim_moves_by_the_forced_law(brown: tuple[jellysim.Scene, Path]) -> None:
    """bell.model = none: roots on a circle at z = 0, moved by A sin(2 pi f t) radially."""
    scene, folder = brown
    with jellysim.open_result(folder) as r:
        time, rim, rim_velocity = r.time, r.rim, r.rim_velocity
    count, radius = scene.tentacles.count, scene.bell.radius
    amplitude, frequency = scene.root_motion.amplitude, scene.root_motion.frequency
    assert amplitude > 0.0
    angles = 2.0 * np.pi * np.arange(count) / count
    radial = np.stack([np.cos(angles), np.sin(angles), np.zeros(count)], axis=1)
    phase = 2.0 * np.pi * frequency * time[:, None, None]
    expected = radial * (radius + amplitude * np.sin(phase))
    expected_velocity = radial * amplitude * 2.0 * np.pi * frequency * np.cos(phase)
    np.testing.assert_allclose(rim, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rim_velocity, expected_velocity, rtol=0, atol=1e-12)


def test_segment_lengths_equal_the_spacing(brown: tuple[jellysim.Scene, Path]) -> None:
    scene, folder = brown
    with jellysim.open_result(folder) as r:
        positions = r.tentacle_positions
    lengths = np.linalg.norm(np.diff(positions, axis=2), axis=3)
    error = np.abs(lengths / scene.tentacles.spacing - 1.0)
    assert error.max() <= 1e-6, f"segment length error {error.max():.3g} at frame " + str(
        np.unravel_index(error.argmax(), error.shape)[0]
    )


def test_single_tentacle_hangs_from_radius_along_minus_z(tmp_path: Path) -> None:
    scene = _run(tmp_path, {"bell.model": "none", "tentacles.count": 1})
    radius, spacing = scene.bell.radius, scene.tentacles.spacing
    particles = scene.tentacles.particles
    with jellysim.open_result(tmp_path) as r:
        x0 = r.tentacle_positions[0, 0]
        rim0 = r.rim[0, 0]
    np.testing.assert_allclose(rim0, [radius, 0.0, 0.0], rtol=0, atol=1e-15)
    expected = np.zeros((particles, 3))
    expected[:, 0] = radius
    expected[:, 2] = -spacing * np.arange(particles)
    np.testing.assert_allclose(x0, expected, rtol=0, atol=1e-12)


def _distance_to_closed_polyline(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Distance of each point (n, 3) to the closed polyline (R, 3)."""
    a = polyline
    b = np.roll(polyline, -1, axis=0)
    ab = b - a
    ap = points[:, None, :] - a[None]
    s = np.clip(np.sum(ap * ab, axis=2) / np.sum(ab * ab, axis=1), 0.0, 1.0)
    nearest = a[None] + s[..., None] * ab[None]
    return np.min(np.linalg.norm(points[:, None, :] - nearest, axis=2), axis=1)


@pytest.mark.parametrize("direction", ["radial", "[0.6, 0.8, 0.0]"])
def test_rim_points_lie_on_the_margin(tmp_path: Path, direction: str) -> None:
    key, value = jellysim.config.parse_override(f"root_motion.direction={direction}")
    _run(tmp_path, {key: value, "tentacles.count": 5})
    with jellysim.open_result(tmp_path) as r:
        rim, margin = r.rim, r.margin
    assert rim.shape[0] == margin.shape[0]
    worst = max(_distance_to_closed_polyline(rim[i], margin[i]).max() for i in range(rim.shape[0]))
    assert worst <= 1e-9, f"a rim point lies {worst:.3g} m off the margin"


def _tentacle_data(folder: Path) -> dict[str, np.ndarray]:
    with jellysim.open_result(folder) as r:
        return _datasets(r.file)


def test_same_seed_is_bitwise_reproducible(tmp_path: Path) -> None:
    overrides = {"seed": 7, "flow.noise": 0.05}
    _run(tmp_path / "a", overrides)
    _run(tmp_path / "b", overrides)
    a, b = _tentacle_data(tmp_path / "a"), _tentacle_data(tmp_path / "b")
    assert a.keys() == b.keys()
    for name in a:
        assert np.array_equal(a[name], b[name]), f"{name} differs between identical runs"


def test_seed_changes_the_noisy_flow_only(tmp_path: Path) -> None:
    noisy = {"flow.noise": 0.05}
    _run(tmp_path / "s1", {**noisy, "seed": 1})
    _run(tmp_path / "s2", {**noisy, "seed": 2})
    one = _tentacle_data(tmp_path / "s1")[fields.TENTACLE_POSITION.path]
    two = _tentacle_data(tmp_path / "s2")[fields.TENTACLE_POSITION.path]
    assert np.array_equal(one[0], two[0])  # the initial state does not depend on the seed
    assert not np.array_equal(one, two)
    assert np.abs(one - two).max() > 1e-6

    # Without noise the seed draws nothing: the tentacles move identically.
    _run(tmp_path / "q1", {"flow.noise": 0.0, "seed": 1})
    _run(tmp_path / "q2", {"flow.noise": 0.0, "seed": 2})
    quiet1 = _tentacle_data(tmp_path / "q1")[fields.TENTACLE_POSITION.path]
    quiet2 = _tentacle_data(tmp_path / "q2")[fields.TENTACLE_POSITION.path]
    assert np.array_equal(quiet1, quiet2)
