"""Everything that reads a result handles tentacle groups (issue 25): ``Result``'s group
accessors on new and older results, ``jellysim plot``, the motion measures and ``jellysim
sweep --tentacle``, on a small scene of two groups of different lengths (three margin tentacles
of 12 particles, two mouth arms of 6: the arms' rows 6..11 are NaN padding)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path

import h5py
import numpy as np
import pytest

import jellysim
from jellysim import fields
from jellysim.errors import InputError
from jellysim.io.motion import motion_by_group, tentacle_motion
from jellysim.io.plots import plot_result
from jellysim.studies import sweep

# Forced roots (bell.model = "none"), a flow and no noise: a second of frames runs in about a
# second. [tentacles] holds the keys the groups share.
TWO_GROUPS = """
name = "two-groups"
duration = 2.0
fps = 30.0

[flow]
speed = 0.1
noise = 0.0

[tentacles]
spacing = 0.01
youngs_modulus = 1000.0

[tentacles.margin]
count = 3
particles = 12

[tentacles.arms]
count = 2
particles = 6
placement = "mouth"
mouth_radius = 0.3

[bell]
model = "none"
radius = 0.05

[root_motion]
amplitude = 0.01
frequency = 2.0
"""

# The margin group alone, as a one-table scene: the same three tentacles.
ONE_GROUP = """
name = "one-group"
duration = 2.0
fps = 30.0

[flow]
speed = 0.1
noise = 0.0

[tentacles]
spacing = 0.01
youngs_modulus = 1000.0
count = 3
particles = 12

[bell]
model = "none"
radius = 0.05

[root_motion]
amplitude = 0.01
frequency = 2.0
"""


def _jellysim(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """``python -m jellysim ARGS`` of this checkout, warnings as errors."""
    source = str(Path(jellysim.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([source, os.environ.get("PYTHONPATH", "")])}
    return subprocess.run(
        [sys.executable, "-W", "error", "-m", "jellysim", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        env=env,
    )


def _run(folder: Path, text: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    scene = folder / "scene-in.toml"
    scene.write_text(text)
    with jellysim.run(jellysim.load_scene(scene), folder / "out", force=True):
        pass
    return folder / "out"


@pytest.fixture(scope="module")
def two(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _run(tmp_path_factory.mktemp("two-groups"), TWO_GROUPS)


@pytest.fixture(scope="module")
def one(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _run(tmp_path_factory.mktemp("one-group"), ONE_GROUP)


@pytest.fixture
def old(one: Path, tmp_path: Path) -> Path:
    """The one-group result as jellysim wrote it before groups: no tentacles/group, no
    tentacles/particles, no attribute tentacle_groups."""
    shutil.copytree(one, tmp_path / "old")
    with h5py.File(tmp_path / "old" / "result.h5", "a") as f:
        del f[fields.TENTACLE_GROUP.path], f[fields.TENTACLE_PARTICLES.path]
        del f.attrs["tentacle_groups"]
    return tmp_path / "old"


def test_group_accessors_of_a_two_group_result(two: Path) -> None:
    with jellysim.open_result(two) as r:
        assert r.tentacle_groups == ["margin", "arms"]
        group, particles = r.tentacle_group, r.tentacle_particles
        assert group.dtype == np.int32 and particles.dtype == np.int32
        np.testing.assert_array_equal(group, [0, 0, 0, 1, 1])
        np.testing.assert_array_equal(particles, [12, 12, 12, 6, 6])
        np.testing.assert_array_equal(r.group_tentacles("arms"), [3, 4])
        padded = r.tentacle_positions
        assert padded.shape == (r.frames, 5, 12, 3)
        assert np.all(np.isnan(padded[:, 3:, 6:])) and np.all(np.isfinite(padded[:, :, :6]))
        arms = r.group_positions("arms")
        assert arms.shape == (r.frames, 2, 6, 3) and np.all(np.isfinite(arms))
        np.testing.assert_array_equal(arms, padded[:, 3:, :6])
        np.testing.assert_array_equal(r.group_positions(0), padded[:, :3])
        np.testing.assert_array_equal(r.group_positions(1, -1), arms[-1])  # one frame
        np.testing.assert_array_equal(r.group_positions("arms", slice(2, 5)), arms[2:5])
        np.testing.assert_array_equal(r.group_velocities("arms"), r.tentacle_velocities[:, 3:, :6])
        # Each arm is its own 6 particles: 5 segments of the spacing.
        lengths = np.linalg.norm(np.diff(arms, axis=2), axis=-1)
        np.testing.assert_allclose(lengths, 0.01, rtol=0.02)
        for wrong in ("tentacles", 2, -1):
            with pytest.raises(InputError, match="0 'margin', 1 'arms'"):
                r.group_positions(wrong)


def test_an_older_result_without_groups_is_one_group(old: Path, one: Path) -> None:
    with jellysim.open_result(old) as r, jellysim.open_result(one) as new:
        assert not r.has(fields.TENTACLE_GROUP) and not r.has(fields.TENTACLE_PARTICLES)
        assert r.tentacle_groups == new.tentacle_groups == ["tentacles"]
        np.testing.assert_array_equal(r.tentacle_group, np.zeros(3, np.int32))
        np.testing.assert_array_equal(r.tentacle_particles, np.full(3, 12, np.int32))
        np.testing.assert_array_equal(new.tentacle_group, r.tentacle_group)
        np.testing.assert_array_equal(new.tentacle_particles, r.tentacle_particles)
        np.testing.assert_array_equal(r.group_positions("tentacles"), r.tentacle_positions)
        assert tentacle_motion(r) == tentacle_motion(new)


def test_a_result_without_tentacles_refuses_the_group_accessors(tmp_path: Path) -> None:
    folder = tmp_path / "none"
    with jellysim.run(
        "forced-tentacles", folder, overrides={"duration": 0.1, "tentacles.count": 1}
    ):
        pass
    with h5py.File(folder / "result.h5", "a") as f:
        del f["tentacles"]
    with jellysim.open_result(folder) as r:
        for accessor in ("tentacle_group", "tentacle_particles"):
            with pytest.raises(InputError, match="tentacles/"):
                getattr(r, accessor)


class _Figures:
    """Every figure saved while it is active, with the warnings raised."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        from matplotlib.figure import Figure

        self.saved: dict[str, Figure] = {}
        save = Figure.savefig

        def keep(figure: Figure, path: object, *args: object, **kwargs: object) -> None:
            self.saved[Path(str(path)).name] = figure
            save(figure, path, *args, **kwargs)

        monkeypatch.setattr(Figure, "savefig", keep)


@pytest.fixture
def figures(monkeypatch: pytest.MonkeyPatch) -> Iterator[_Figures]:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a NaN warning fails the test
        yield _Figures(monkeypatch)


def _lines(figure: object) -> list[np.ndarray]:
    return [
        np.asarray(line.get_xydata(), dtype=float)
        for ax in figure.axes  # type: ignore[attr-defined]
        for line in ax.get_lines()
    ]


def test_plots_of_a_two_group_result(two: Path, tmp_path: Path, figures: _Figures) -> None:
    with jellysim.open_result(two) as r:
        paths = plot_result(r, tmp_path / "plots")
        padded = r.tentacle_positions
    assert [p.name for p in paths] == ["root_tip_trace.png", "tentacle_shapes.png"]
    assert all(p.stat().st_size > 10_000 for p in paths)
    for name, figure in figures.saved.items():
        for xy in _lines(figure):
            assert np.all(np.isfinite(xy)), name  # no NaN-padded rows drawn
    trace = figures.saved["root_tip_trace.png"]
    assert len(trace.axes) == 2  # a panel per group
    assert "margin" in trace.axes[0].get_title() and "arms" in trace.axes[1].get_title()
    # The arms' panel: tentacle 3's root and its own tip (particle 5), not a NaN row.
    root, tip = (line.get_ydata() for line in trace.axes[1].get_lines())
    np.testing.assert_array_equal(root, padded[:, 3, 0, 0])
    np.testing.assert_array_equal(tip, padded[:, 3, 5, 0])
    shapes = figures.saved["tentacle_shapes.png"]
    legend = shapes.axes[0].get_legend()
    assert [t.get_text() for t in legend.get_texts()] == ["margin (3)", "arms (2)"]
    # Per snapshot: the margin ring, then per tentacle its chain and its tip marker.
    first = shapes.axes[0].get_lines()
    chains = first[1::2]
    assert [len(c.get_xdata()) for c in chains] == [12, 12, 12, 6, 6]
    colours = [c.get_color() for c in chains]
    assert len(set(colours[:3])) == 1 and len(set(colours[3:])) == 1  # a colour per group
    assert colours[0] != colours[3]


def test_plots_of_a_preset_with_a_bell_and_groups(tmp_path: Path, figures: _Figures) -> None:
    """purple-jelly (marginal tentacles and oral arms under a kinematic bell): Fig. 9 draws each
    group interpolated on its own, its simulated chains over them, a legend per group."""
    folder = tmp_path / "pj"
    overrides = {"duration": 0.8, "tentacles.marginal.count": 4}
    with jellysim.run("purple-jelly", folder, overrides=overrides) as r:
        paths = plot_result(r, tmp_path / "plots")
    assert "jetting_and_relaxation.png" in [p.name for p in paths]
    for name, figure in figures.saved.items():
        for xy in _lines(figure):
            assert np.all(np.isfinite(xy)), name
    jet = figures.saved["jetting_and_relaxation.png"]
    labels = [t.get_text() for t in jet.axes[0].get_legend().get_texts()]
    assert labels == [
        "marginal (simulated)",
        "oral_arms (simulated)",
        "marginal (drawn)",
        "oral_arms (drawn)",
    ]


def test_jellysim_plot_prints_no_warning(two: Path, tmp_path: Path) -> None:
    done = _jellysim(tmp_path, "plot", str(two), "--out", "figs")
    assert done.returncode == 0 and done.stderr == "", done.stderr
    assert len(done.stdout.split()) == 2


def test_motion_per_group(two: Path, one: Path) -> None:
    with jellysim.open_result(two) as r, jellysim.open_result(one) as alone:
        groups = motion_by_group(r)
        assert list(groups) == ["margin", "arms"]
        # The margin group moves as the same tentacles alone (groups do not interact here), so
        # its measures are the one-group scene's.
        margin, reference = groups["margin"], tentacle_motion(alone)
        for name in ("chord", "bend", "bend_peak", "lag", "period", "coherence"):
            assert getattr(margin, name) == pytest.approx(getattr(reference, name), abs=1e-9)
        # One group: the group's measures are the whole result's.
        assert motion_by_group(alone) == {"tentacles": reference}
        assert tentacle_motion(alone, group=0) == reference
        # The arms: finite (never the NaN padding), each its own 6 particles.
        arms = groups["arms"]
        assert 0.9 < arms.chord <= 1.0 and 0.0 <= arms.bend < 0.1
        everything = tentacle_motion(r)
        for m in (margin, arms, everything):
            values = (m.chord, m.bend, m.bend_peak, m.lag, m.period, m.coherence)
            assert np.all(np.isfinite(values))
        # All tentacles: the chord is the mean over five chains of both groups'.
        assert everything.chord == pytest.approx((3 * margin.chord + 2 * arms.chord) / 5)


def test_sweep_numbers_tentacles_across_groups(two: Path, tmp_path: Path) -> None:
    scene = tmp_path / "two.toml"
    scene.write_text(TWO_GROUPS)
    (trace,) = sweep(scene, "flow.speed", [0.1], tentacle=3)  # the first arm
    with jellysim.open_result(two) as r:
        positions = r.tentacle_positions
    np.testing.assert_array_equal(trace.root_x, positions[:, 3, 0, 0])
    np.testing.assert_array_equal(trace.tip_x, positions[:, 3, 5, 0])  # its own tip
    assert np.all(np.isfinite(trace.tip_x))
    with pytest.raises(InputError, match=r"tentacles 0\.\.4 \(0\.\.2 margin, 3\.\.4 arms\)"):
        sweep(scene, "flow.speed", [0.1], tentacle=5)
    done = _jellysim(
        tmp_path, "sweep", str(scene), "--key", "flow.speed", "--values", "0.1", "--tentacle", "-1"
    )
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "jellysim: error: --tentacle -1: the scene has tentacles 0..4 (0..2 margin, 3..4 arms)"
    ]
