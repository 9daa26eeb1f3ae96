"""``jellysim render`` with the system POV-Ray on tiny frames: scene files parse, frames show the
jellyfish inside the picture, interrupted renders resume, bad input exits 2."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

import jellysim
from jellysim.render import povray
from jellysim.render.frame import Frame
from jellysim.render.pipeline import frame_cameras, make_members, render

pytestmark = pytest.mark.skipif(
    povray.find_povray() is None and not os.environ.get("CI"),
    reason="POV-Ray is not installed (sudo apt-get install povray); CI installs it",
)

SIZE = (64, 48)


@pytest.fixture(scope="module")
def brown(tmp_path_factory: pytest.TempPathFactory) -> jellysim.Result:
    folder = tmp_path_factory.mktemp("brown")
    return jellysim.run("brown-jelly", folder, overrides={"duration": 0.2, "fps": 15.0})


def _render_text(text: str, folder: Path, name: str) -> np.ndarray:
    scene = folder / f"{name}.pov"
    scene.write_text(text, encoding="utf-8")
    image = folder / f"{name}.png"
    povray.render_file(
        povray.find_povray() or "povray", scene, image, SIZE, povray.QUALITIES["draft"], 1
    )
    return matplotlib.image.imread(image)[..., :3]


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_a_frame_shows_the_jellyfish_inside_the_picture(
    brown: jellysim.Result, tmp_path: Path, quality: str
) -> None:
    members = make_members([brown], 1, None, 0)
    cameras, extent, _ = frame_cameras(members, brown.frames, SIZE, "auto")
    level = povray.QUALITIES[quality]
    frame = Frame(time=0.0, jellyfish=[members[0].frame(2)])
    empty = Frame(time=0.0, jellyfish=[])
    water_color = members[0].look.water_color
    picture = _render_text(
        povray.scene_text(frame, cameras[2], SIZE, level, extent, water=water_color), tmp_path, "j"
    )
    water = _render_text(
        povray.scene_text(empty, cameras[2], SIZE, level, extent, water=water_color), tmp_path, "w"
    )
    assert picture.shape == (SIZE[1], SIZE[0], 3)
    jelly = np.abs(picture - water).max(axis=2) > 0.02  # pixels that differ from the background
    assert jelly.sum() > 0.05 * jelly.size  # not blank: the jellyfish covers a good part
    rows, columns = np.nonzero(jelly)
    # Inside the picture, with at least one pixel of water around it.
    assert rows.min() > 0 and columns.min() > 0
    assert rows.max() < SIZE[1] - 1 and columns.max() < SIZE[0] - 1
    # Centred: the bell's margin centre is near the middle column.
    assert abs(0.5 * (columns.min() + columns.max()) - SIZE[0] / 2) < 0.15 * SIZE[0]


def test_render_resumes_only_the_missing_frames(brown: jellysim.Result, tmp_path: Path) -> None:
    out = tmp_path / "render"
    first = render([brown], out, renderer="povray", size=SIZE, video=False)
    frames = sorted((out / "frames").glob("frame_*.png"))
    assert first["rendered"] == brown.frames == len(frames)
    assert len(list((out / "pov").glob("frame_*.pov"))) == brown.frames
    kept = frames[0].stat().st_mtime_ns
    frames[1].unlink()
    second = render([brown], out, renderer="povray", size=SIZE, video=False)
    assert (second["rendered"], second["kept"]) == (1, brown.frames - 1)
    assert frames[1].is_file() and frames[0].stat().st_mtime_ns == kept
    assert not list((out / "frames").glob("*.part.png"))


def test_the_same_render_writes_the_same_scenes(brown: jellysim.Result, tmp_path: Path) -> None:
    """Final quality, with its snow, shafts and focal blur: two renders of the same frames write
    the same .pov text, and the water's particles drift a little from one frame to the next."""
    texts = []
    for name in ("a", "b"):
        out = tmp_path / name
        render([brown], out, renderer="povray", quality="final", size=SIZE, video=False)
        texts.append([f.read_text() for f in sorted((out / "pov").glob("frame_*.pov"))])
    assert texts[0] == texts[1] and len(texts[0]) == brown.frames
    assert "focal_point" in texts[0][0] and "cylinder {" in texts[0][0]
    assert texts[0][0] != texts[0][1]


def test_a_school_and_the_room_render(brown: jellysim.Result, tmp_path: Path) -> None:
    out = tmp_path / "school"
    done = render(
        [brown], out, renderer="povray", size=SIZE, video=False, school=3, room=True, frames=(0, 1)
    )
    assert done["rendered"] == 1
    text = (out / "pov" / "frame_00000.pov").read_text()
    # three bells and the three jellyfish's oral arms (one ribbon mesh2 each), the tiled floor
    assert text.count("mesh2 {") == 3 * 2 and "checker" in text
    members = make_members([brown], 3, None, 0)
    offsets = np.array([m.offset for m in members])
    assert np.linalg.norm(offsets[0] - offsets[1]) > 0.5 * 0.3  # spread apart
    assert len({m.look.bell_color for m in members}) == 3  # different colours


def _cli(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "jellysim", "render", *args],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (("{missing}",), "no result"),
        (("{result}", "--size", "64by48"), "--size"),
        (("{result}", "--size", "4x4"), "--size"),
        (("{result}", "--frames", "5:2"), "--frames"),
        (("{result}", "--out", "{file}/sub"), "--out"),
        (("{result}", "--set", "flow.speed=1"), "look"),
        (("{result}", "--school", "0"), "--school"),
    ],
    ids=["no-result", "size-syntax", "size-small", "frames", "unwritable", "not-look", "school"],
)
def test_bad_input_exits_2_with_one_line(
    brown: jellysim.Result, tmp_path: Path, args: tuple[str, ...], fragment: str
) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    filled = [a.format(missing=tmp_path / "none", result=brown.folder, file=blocker) for a in args]
    done = _cli(*filled, "--no-video", "--quiet")
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0] and "Traceback" not in done.stderr
    assert not (brown.folder / "render").exists()  # nothing written


def test_povray_asked_for_but_missing_exits_2(brown: jellysim.Result, tmp_path: Path) -> None:
    env = {**os.environ, "PATH": str(Path(sys.executable).parent)}
    done = _cli(str(brown.folder), "--renderer", "povray", "--out", str(tmp_path / "r"), env=env)
    assert done.returncode == 2
    assert "apt-get install povray" in done.stderr and len(done.stderr.strip().splitlines()) == 1
