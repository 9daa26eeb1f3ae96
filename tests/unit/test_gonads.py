"""The horseshoe gonads (``look.gonads``, issue 25): placed just under the subumbrella of the
bell's surface, open towards the margin, following the bell; in POV-Ray's scene text only when
set; in the preview in their colour inside the bell's outline."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
from matplotlib.image import imread

from jellysim.bell.kinematic import bell_faces
from jellysim.config import load_scene
from jellysim.render import povray
from jellysim.render.frame import Camera, Frame, Jellyfish
from jellysim.render.pipeline import gonads, scene_look
from jellysim.render.preview import render_preview

RADIUS, HEIGHT, WALL = 1.0, 0.5, 0.12
RINGS, SECTORS = 8, 32


def shell(
    radius: float = RADIUS, height: float = HEIGHT, offset: tuple[float, float, float] = (0, 0, 0)
) -> tuple[np.ndarray, np.ndarray]:
    """A closed bell shell in the topology of :func:`bell_faces`: outer and inner half
    ellipsoids ``WALL`` apart, vertices (V, 3) m and faces (M, 3), its margin at z = 0."""
    s = np.arange(1, RINGS + 1) / RINGS
    ring_s = np.concatenate([s, s[-2::-1]])
    outer = np.arange(len(ring_s)) < RINGS
    a = 0.5 * np.pi * ring_s
    r = np.where(outer, radius, radius - WALL)
    h = np.where(outer, height, height - WALL)
    angles = 2.0 * np.pi * np.arange(SECTORS) / SECTORS
    rho = (r * np.sin(a))[:, None] * np.ones(SECTORS)
    z = (h * np.cos(a))[:, None] * np.ones(SECTORS)
    rings = np.stack([rho * np.cos(angles), rho * np.sin(angles), z], axis=-1).reshape(-1, 3)
    vertices = np.concatenate([[[0.0, 0.0, height]], rings, [[0.0, 0.0, height - WALL]]])
    return vertices + np.asarray(offset), bell_faces(SECTORS, RINGS)


def inner_height(rho: np.ndarray) -> np.ndarray:
    """The inner (subumbrellar) ellipsoid's height over the margin at distance ``rho``."""
    return (HEIGHT - WALL) * np.sqrt(np.clip(1.0 - (rho / (RADIUS - WALL)) ** 2, 0.0, None))


def test_four_horseshoes_lie_on_the_subumbrella_open_towards_the_margin() -> None:
    vertices, faces = shell()
    drawn = gonads(vertices, faces, np.zeros(3), 4)
    assert drawn is not None
    assert drawn.paths.shape[0] == 4
    rho = np.linalg.norm(drawn.paths[..., :2], axis=-1)
    # Just under the inner surface, the tube touching it (to the mesh's faceting, a chord's
    # sag), not under the outer one.
    top = drawn.paths[..., 2] + drawn.radius
    assert np.abs(top - inner_height(rho)).max() < 0.02
    assert rho.max() < RADIUS - WALL
    for k, path in enumerate(drawn.paths):
        azimuth = 2.0 * math.pi * (k + 0.5) / 4  # interradial: between the arms' 0, 90, ...
        middle = path.mean(axis=0)[:2]
        direction = np.array([math.cos(azimuth), math.sin(azimuth)])
        along = path[:, :2] @ direction
        # The open ends point outwards: both ends farther out along the horseshoe's own
        # direction than its closed middle, which is its point nearest the axis.
        assert along[0] > along[len(along) // 2] and along[-1] > along[len(along) // 2]
        assert int(np.argmin(np.linalg.norm(path[:, :2], axis=1))) == len(path) // 2
        assert np.dot(middle, direction) > 0.3 * RADIUS  # on its own interradius
    assert gonads(vertices, faces, np.zeros(3), 0) is None


def test_the_gonads_follow_the_bell() -> None:
    vertices, faces = shell()
    move = np.array([0.3, -0.2, 0.7])
    here = gonads(vertices, faces, np.zeros(3), 4)
    there = gonads(vertices + move, faces, move, 4)
    assert here is not None and there is not None
    np.testing.assert_allclose(there.paths, here.paths + move, atol=1e-12)
    # A contracted bell (narrower and taller) draws them nearer the axis, on its new surface.
    squeezed = gonads(*shell(0.8 * RADIUS, 1.2 * HEIGHT), np.zeros(3), 4)
    assert squeezed is not None
    ratio = np.linalg.norm(squeezed.paths[..., :2], axis=-1) / np.linalg.norm(
        here.paths[..., :2], axis=-1
    )
    np.testing.assert_allclose(ratio, 0.8, rtol=1e-9)
    assert squeezed.paths[..., 2].mean() > here.paths[..., 2].mean()


CAMERA = Camera(np.array([0.0, -4.0, 1.6]), np.array([0.0, 0.0, 0.2]))
SIZE = (160, 120)


def jelly(count: int) -> Jellyfish:
    look = scene_look(load_scene("moon-jelly"))
    look = replace(look, gonads=count)
    vertices, faces = shell()
    tentacles = np.stack([np.linspace([0.9, 0.0, 0.0], [0.9, 0.0, -0.4], 8)] * 2)
    return Jellyfish(
        tentacles, vertices, faces, look, gonads=gonads(vertices, faces, np.zeros(3), count)
    )


def test_the_gonads_are_in_the_povray_scene_only_when_set() -> None:
    level = povray.QUALITIES["final"]
    without = povray.scene_text(Frame(0.0, [jelly(0)]), CAMERA, SIZE, level, 2.0)
    unset = jelly(0)
    bare = Jellyfish(unset.tentacles, unset.bell_vertices, unset.bell_faces, unset.look)
    assert without == povray.scene_text(Frame(0.0, [bare]), CAMERA, SIZE, level, 2.0)
    assert povray.gonads_block(unset, True) == ""
    with_four = povray.scene_text(Frame(0.0, [jelly(4)]), CAMERA, SIZE, level, 2.0)
    block = povray.gonads_block(jelly(4), True)
    assert block and block in with_four
    assert with_four.replace("// object gonads\n" + block, "") == without
    assert block.count("cone{") == 4 * (jelly(4).gonads.paths.shape[1] - 1)  # type: ignore[union-attr]
    color = jelly(4).look.gonad_color
    assert f"rgb <{color[0]:.4g},{color[1]:.4g},{color[2]:.4g}>" in block


def test_the_preview_shows_gonad_coloured_pixels_inside_the_bell(tmp_path: Path) -> None:
    def pixels(count: int) -> np.ndarray:
        path = render_preview(
            Frame(0.0, [jelly(count)]), CAMERA, SIZE, tmp_path / f"g{count}.png", "draft"
        )
        return imread(path)[..., :3].astype(np.float64)

    plain, drawn = pixels(0), pixels(4)
    changed = np.abs(drawn - plain).sum(axis=2) > 0.05
    assert changed.sum() > 30
    # Violet: more blue than green where they changed the picture, unlike the pale bell.
    assert (drawn[changed][:, 2] > drawn[changed][:, 1] + 0.05).mean() > 0.8
    # Inside the bell's outline: the columns and rows the bell spans in the plain picture.
    nothing = Jellyfish(np.empty((0, 2, 3)), None, None, jelly(0).look)
    background = imread(
        render_preview(Frame(0.0, [nothing]), CAMERA, SIZE, tmp_path / "empty.png", "draft")
    )[..., :3]
    bell = np.abs(plain - background).sum(axis=2) > 0.02
    rows, columns = np.nonzero(changed)
    bell_rows, bell_columns = np.nonzero(bell)
    assert bell_columns.min() <= columns.min() and columns.max() <= bell_columns.max()
    assert bell_rows.min() <= rows.min() and rows.max() <= bell_rows.max()
    assert bell[changed].mean() > 0.95
