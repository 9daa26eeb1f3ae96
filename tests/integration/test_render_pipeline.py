"""``jellysim render`` end to end: the movie (frame count, size, duration), the preview renderer
without POV-Ray, and results without tentacles (fluid only)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import matplotlib.image
import numpy as np
import pytest

import jellysim
from jellysim import fields
from jellysim.render import povray
from jellysim.render.frame import FLUID_COLOR
from jellysim.render.pipeline import make_members, render
from jellysim.render.video import probe


@pytest.fixture(scope="module")
def brown(tmp_path_factory: pytest.TempPathFactory) -> jellysim.Result:
    folder = tmp_path_factory.mktemp("brown")
    return jellysim.run("brown-jelly", folder, overrides={"duration": 0.5, "fps": 12.0})


def test_preview_renders_a_movie_without_povray_on_the_path(
    brown: jellysim.Result, tmp_path: Path
) -> None:
    out = tmp_path / "movie"
    env = {**os.environ, "PATH": str(Path(sys.executable).parent)}  # no povray, no ffmpeg
    done = subprocess.run(
        [sys.executable, "-m", "jellysim", "render", str(brown.folder), "--out", str(out)]
        + ["--size", "96x72", "--gif", "--quiet"],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "preview renderer" in done.stderr  # the notice
    info = probe(out / "movie.mp4")
    assert info["frames"] == brown.frames == 7
    assert (info["width"], info["height"]) == (96, 72)
    assert info["duration"] == pytest.approx(brown.frames / 12.0, abs=0.02)
    assert info["codec"] == "h264" and info["pix_fmt"] == "yuv420p"
    assert (out / "movie.gif").stat().st_size > 0
    picture = matplotlib.image.imread(out / "frames" / "frame_00003.png")[..., :3]
    assert picture.shape == (72, 96, 3) and picture.std() > 0.02  # not blank
    assert str(out / "movie.mp4") in done.stdout


def _fluid_result(folder: Path, dead: int) -> Path:
    """A hand-made fluid-only result (the layout of DESIGN §3): a 2-D block of particles
    falling, ``dead`` of them marked as left the domain."""
    folder.mkdir()
    frames, side = 4, 10
    x, y = np.meshgrid(np.arange(side) * 0.01, np.arange(side) * 0.01)
    block = np.stack([x.ravel(), y.ravel()], axis=1)
    positions = np.stack([block - [0.0, 0.002 * f] for f in range(frames)])
    alive = np.ones((frames, side * side), dtype=bool)
    alive[:, :dead] = False
    with h5py.File(folder / "result.h5", "w") as f:
        f[fields.TIME.path] = np.arange(frames) / 10.0
        f[fields.FLUID_POSITION.path] = positions
        f[fields.FLUID_ALIVE.path] = alive
        f.attrs["scene"] = 'name = "block"\nfps = 10.0\nduration = 0.3\n'
        f.attrs["fps"] = 10.0
        f.attrs["frames_expected"] = frames
    return folder


@pytest.mark.parametrize("renderer", ["preview", "povray"])
def test_fluid_only_results_render_their_live_particles(tmp_path: Path, renderer: str) -> None:
    if renderer == "povray" and povray.find_povray() is None and not os.environ.get("CI"):
        pytest.skip("POV-Ray is not installed")
    with jellysim.open_result(_fluid_result(tmp_path / "fluid", dead=7)) as result:
        members = make_members([result], 1, None, 0)
        assert members[0].groups == ()
        points = members[0].fluid_points(2)
        assert points.shape == (93, 3) and np.all(points[:, 1] == 0.0)  # (x, y) -> (x, 0, y)
        done = render([result], tmp_path / "r", renderer=renderer, size=(48, 48), video=False)
    assert done["rendered"] == 4
    picture = matplotlib.image.imread(tmp_path / "r" / "frames" / "frame_00000.png")[..., :3]
    assert picture.std() > 0.02
    if renderer == "povray":
        text = (tmp_path / "r" / "pov" / "frame_00000.pov").read_text()
        assert text.count("sphere{") == 93  # the live particles only


def test_a_phase_shift_shifts_the_pulse_not_the_place(brown: jellysim.Result) -> None:
    members = make_members([brown], 4, None, 3)
    assert len({m.phase for m in members}) > 1
    first = members[0].centres() - members[0].offset
    for member in members[1:]:
        centres = member.centres() - member.offset
        # Same mean swim: the heights differ only by the pulse's wobble about the mean line
        # (a shifted pulse moves brown-jelly by at most 0.1 m about its mean swim).
        assert np.abs(centres[:, 2] - first[:, 2]).max() < 0.1


def test_fluid_around_a_jellyfish_is_left_out_unless_asked(
    brown: jellysim.Result, tmp_path: Path
) -> None:
    """--fluid auto draws no particles when a jellyfish swims in the fluid (the tank would hide
    it) and frames the jellyfish; --fluid spheres draws every live particle."""
    if povray.find_povray() is None and not os.environ.get("CI"):
        pytest.skip("POV-Ray is not installed")
    folder = tmp_path / "in-water"
    folder.mkdir()
    shutil.copy(brown.path, folder / "result.h5")
    frames, count = brown.frames, 40
    rng = np.random.default_rng(1)
    with h5py.File(folder / "result.h5", "a") as f:
        f[fields.FLUID_POSITION.path] = rng.uniform(-3.0, 3.0, (frames, count, 3))
        f[fields.FLUID_ALIVE.path] = np.ones((frames, count), dtype=bool)
    spheres = {}
    with jellysim.open_result(folder) as result:
        for mode in ("auto", "spheres", "none"):
            out = tmp_path / mode
            render([result], out, fluid=mode, size=(32, 32), frames=(0, 1), video=False)
            text = (out / "pov" / "frame_00000.pov").read_text()
            # The fluid's spheres: one line, one union, in the fluid's colour (the tentacles'
            # joints and the water's drifting particles are spheres too).
            fluid_color = "rgbt <{},{},{},0.6>".format(*FLUID_COLOR)
            spheres[mode] = sum(
                line.count("sphere{") for line in text.splitlines() if fluid_color in line
            )
        with pytest.raises(jellysim.InputError, match="--fluid"):
            render([result], tmp_path / "bad", fluid="cubes", size=(32, 32), video=False)
    assert spheres["auto"] == spheres["none"] == 0
    assert spheres["spheres"] == count


@pytest.fixture(scope="module")
def purple(tmp_path_factory: pytest.TempPathFactory) -> jellysim.Result:
    folder = tmp_path_factory.mktemp("purple")
    return jellysim.run("purple-jelly", folder, overrides={"duration": 0.3, "fps": 10.0})


@pytest.fixture(scope="module")
def one_group(tmp_path_factory: pytest.TempPathFactory) -> jellysim.Result:
    """brown-jelly's marginal tentacles alone (its oral arms are a second group): one group."""
    scene = jellysim.load_scene("brown-jelly", {"duration": 0.5, "fps": 12.0}).group_scene(0)
    return jellysim.run(scene, tmp_path_factory.mktemp("one-group"))


def test_a_one_group_result_draws_as_before_groups(one_group: jellysim.Result) -> None:
    """The pipeline's groups against the path it replaced: the whole result's drawn tentacles
    in the jellyfish's own look (Jellyfish.tentacles), the text byte for byte."""
    from dataclasses import replace

    from jellysim.interpolation import interpolate_result
    from jellysim.render.frame import Frame
    from jellysim.render.pipeline import frame_cameras

    (member,) = make_members([one_group], 1, None, 0, fluid=False)
    cameras, extent, _ = frame_cameras([member], one_group.frames, (64, 48), "auto")
    drawn = interpolate_result(one_group)
    for index in (0, one_group.frames - 1):
        new = member.frame(index)
        old = replace(new, tentacles=drawn[index], groups=(), centre=None)
        for quality in povray.QUALITIES.values():
            texts = [
                povray.scene_text(Frame(0.0, [j]), cameras[index], (64, 48), quality, extent)
                for j in (new, old)
            ]
            assert texts[0] == texts[1]


def test_oral_arms_are_ribbons_on_a_manubrium_and_no_nan_is_drawn(purple: jellysim.Result) -> None:
    from jellysim.render.frame import Frame
    from jellysim.render.pipeline import frame_cameras

    assert np.isnan(purple.read(fields.TENTACLE_POSITION, 0)).any()  # the padded store
    members = make_members([purple], 2, None, 0, fluid=False)
    cameras, extent, _ = frame_cameras(members, purple.frames, (64, 48), "auto")
    assert np.isfinite(extent)
    assert all(np.isfinite(c.location).all() for c in cameras)
    jelly = members[1].frame(1)
    marginal, arms = jelly.groups
    assert (marginal.look.form, arms.look.form) == ("thread", "ribbon")
    assert marginal.positions.shape == (32, 41, 3) and arms.positions.shape == (4, 25, 3)
    assert np.isfinite(marginal.positions).all() and np.isfinite(arms.positions).all()
    assert arms.first == 32
    # The manubrium reaches from inside the bell down to the arms' roots.
    stalk = jelly.manubrium
    assert stalk is not None and jelly.bell_vertices is not None and jelly.centre is not None
    roots = arms.positions[:, 0]
    assert np.allclose(stalk.bottom, roots.mean(axis=0))
    assert stalk.top[2] > jelly.centre[2] and stalk.top[2] < jelly.bell_vertices[:, 2].max()
    assert np.linalg.norm(stalk.top[:2] - jelly.centre[:2]) < 0.2 * 0.05
    text = povray.scene_text(
        Frame(0.0, [members[0].frame(1)]), cameras[1], (64, 48), povray.QUALITIES["final"], extent
    )
    assert "nan" not in text.lower()
    assert text.count("mesh2 {") == 2 and "cone { " in text
    # A school shifts each group's hue: the second jellyfish's arms are not the first's colour.
    assert members[1].groups[1].look.color != members[0].groups[1].look.color
