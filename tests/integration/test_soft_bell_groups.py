"""Oral arms on the soft bell (issue 25): Case 2's moon jelly with its marginal group and its group
of four ribbon arms placed at the mouth, as the moon-jelly presets carry them. At the test scale
of tests/scenes.py (SMALL_MOON, l0 = 0.25 m)
for a few frames: it runs, the arms' roots sit on their circle inside the margin, under the
bell, and the preview draws the arms in their colour (the picture with them against the same
frame without them)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scenes
from matplotlib.image import imread

import jellysim
from jellysim.config.scenes import scene_source_tree
from jellysim.render.frame import Frame, Jellyfish
from jellysim.render.pipeline import frame_cameras, make_members
from jellysim.render.preview import make_view, project, render_preview

ARM_COLOR = [0.2, 0.25, 0.9]  # a blue no other part of the moon jelly has: easy to find
CASE_2 = ("moon-jelly", "moon-jelly-weightless", "moon-jelly-real-size", "moon-jelly-fine")


def grouped_moon_tree() -> dict[str, Any]:
    """The moon-jelly preset shrunk for a test: four marginal tentacles, the arms 0.84 m long
    (8 particles 0.12 m apart, so that they stay above the small tank's floor) and in
    ``ARM_COLOR``."""
    tree = scene_source_tree("moon-jelly")
    tentacles = tree["tentacles"]
    tentacles["count"] = 4
    tentacles["oral_arms"].update(particles=8, spacing=0.12, color=ARM_COLOR)
    return tree


@pytest.mark.parametrize("preset", CASE_2)
def test_the_case_2_presets_carry_the_paper_s_tentacles_and_four_ribbon_arms(preset: str) -> None:
    scene = jellysim.load_scene(preset)
    assert [g.name for g in scene.groups] == ["marginal", "oral_arms"]
    marginal, arms = (g.tentacles for g in scene.groups)
    assert (marginal.count, marginal.particles) == (10, 20)  # the paper's Case 2
    assert marginal.placement in (None, "margin")
    assert (arms.count, arms.placement, arms.form) == (4, "mouth", "ribbon")
    length = (arms.particles - 1) * arms.spacing
    assert 0.9 * scene.bell.radius <= length <= 1.1 * scene.bell.radius  # as long as the radius
    # --set tentacles.count still sets the fringe (the arms keep their four).
    fewer = jellysim.load_scene(preset, {"tentacles.count": 2})
    assert [g.tentacles.count for g in fewer.groups] == [2, 4]


@pytest.fixture(scope="module")
def arms_result(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("soft-bell-groups")
    overrides = {**scenes.SMALL_MOON, "duration": 0.3, "fps": 10.0}
    scene = jellysim.load_scene(grouped_moon_tree(), overrides)
    with jellysim.run(scene, folder, force=True):
        pass
    return folder


def test_the_arms_hang_from_inside_the_margin_under_the_bell(arms_result: Path) -> None:
    with jellysim.open_result(arms_result) as result:
        assert result.frames == 4
        assert result.tentacle_groups == ["marginal", "oral_arms"]
        positions = result.group_positions("oral_arms")  # (F, 4, P, 3)
        margin = result.margin  # (F, R, 3)
        vertices = result.bell_surface_vertices
    assert np.isfinite(positions[:, :, :8]).all()
    for frame in range(positions.shape[0]):
        centre = margin[frame].mean(axis=0)
        margin_radius = np.linalg.norm((margin[frame] - centre)[:, :2], axis=1).mean()
        roots = positions[frame, :, 0]
        radial = np.linalg.norm((roots - centre)[:, :2], axis=1)
        assert radial.max() < 0.5 * margin_radius  # well inside the margin
        np.testing.assert_allclose(radial, radial.mean(), rtol=0.05)  # on one circle
        # Under the bell: below the bell's surface straight above them, not below the margin.
        above = np.linalg.norm((vertices[frame] - roots[:, None])[..., :2], axis=2) < 0.3
        for k in range(len(roots)):
            assert vertices[frame][above[k], 2].min() > roots[k, 2]
        assert roots[:, 2].max() <= centre[2] + 0.3  # about the margin plane


def test_the_preview_draws_the_arms(arms_result: Path, tmp_path: Path) -> None:
    size = (240, 180)
    with jellysim.open_result(arms_result) as result:
        members = make_members([result], 1, None, 0, fluid=False)
        cameras, _, _ = frame_cameras(members, result.frames, size, "auto")
        jelly = members[0].frame(3)
    camera = cameras[3]
    without = replace(jelly, groups=tuple(g for g in jelly.groups if g.look.form != "ribbon"))

    def pixels(drawn: Jellyfish, name: str) -> np.ndarray:
        path = render_preview(Frame(0.3, [drawn]), camera, size, tmp_path / name, "draft")
        return imread(path)[..., :3].astype(np.float64)

    arms = pixels(jelly, "arms.png") - pixels(without, "bare.png")
    changed = np.abs(arms).sum(axis=2) > 0.03
    assert changed.sum() > 30  # the arms, seen through the bell and the fringe
    assert (arms[changed][:, 2] - arms[changed][:, 0]).mean() > 0.02  # bluer: their colour
    # Below the margin's centre on screen: hanging from the mouth.
    assert jelly.centre is not None
    margin_row = project(jelly.centre, make_view(camera, *size))[0][1]
    assert np.nonzero(changed)[0].mean() > margin_row


def test_the_preset_s_gonads_follow_the_soft_bell(arms_result: Path) -> None:
    with jellysim.open_result(arms_result) as result:
        assert result.scene.look.gonads == 4  # the moon-jelly preset's look
        member = make_members([result], 1, None, 0, fluid=False)[0]
        jellies = [member.frame(k) for k in range(result.frames)]
        margin = result.margin
    for jelly, ring in zip(jellies, margin, strict=True):
        assert jelly.gonads is not None and jelly.centre is not None
        points = jelly.gonads.paths.reshape(-1, 3)
        # Centred on this frame's bell axis, inside its margin, above the margin plane.
        np.testing.assert_allclose(points[:, :2].mean(axis=0), jelly.centre[:2], atol=1e-9)
        reach = np.linalg.norm((points - jelly.centre)[:, :2], axis=1)
        assert reach.max() < np.linalg.norm((ring - jelly.centre)[:, :2], axis=1).min()
        assert points[:, 2].min() > jelly.centre[2]
