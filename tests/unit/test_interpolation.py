"""Cosine interpolation of tentacles (paper §4.1.3; DESIGN §2 "Interpolation")."""

import numpy as np
import pytest

import jellysim
from jellysim.interpolation import (
    cosine_weight,
    interpolate_result,
    interpolate_tentacles,
    interpolation_lags,
    local_frames,
    margin_point,
)


@pytest.fixture(scope="module")
def brown(tmp_path_factory):
    folder = tmp_path_factory.mktemp("brown")
    return jellysim.run("brown-jelly", folder, overrides={"duration": 3.0})


def test_cosine_weights_as_data():
    t = np.linspace(0, 1, 11)
    w = cosine_weight(t)
    assert w[0] == 0.0 and w[-1] == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_allclose(w + cosine_weight(1 - t), 1.0, atol=1e-15)  # partition of unity
    assert np.all(np.diff(w) > 0)
    assert cosine_weight(0.5) == pytest.approx(0.5, abs=1e-15)


def test_a_window_of_frames_equals_the_slice_of_the_whole(brown):
    whole = interpolate_result(brown, 3)
    period = brown.scene.bell.period
    fps = brown.file.attrs["fps"]
    assert 0.25 * period * fps > 2  # the lag reaches several frames back
    for start, stop in ((0, 4), (1, 2), (17, 40), (whole.shape[0] - 5, whole.shape[0])):
        window = interpolate_result(brown, 3, frames=(start, stop))
        np.testing.assert_allclose(window, whole[start:stop], rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="outside"):
        interpolate_result(brown, 3, frames=(5, 5))


def test_frames_before_first_are_read_but_not_drawn(brown):
    # What a window costs is the frames drawn (the viewer bounds its answers by them), not the
    # frames its lag reads: those before ``first`` are inputs only, and the frames drawn are
    # the same numbers as when every frame is drawn.
    positions, margin = brown.tentacle_positions, brown.margin
    whole = interpolate_tentacles(positions, margin, brown.time, 3, 0.01, lag_spread=0.25)
    for first in (1, 17, whole.shape[0] - 1):
        tail = interpolate_tentacles(
            positions, margin, brown.time, 3, 0.01, lag_spread=0.25, first=first
        )
        assert tail.shape == (whole.shape[0] - first, *whole.shape[1:])
        np.testing.assert_array_equal(tail, whole[first:])
    with pytest.raises(ValueError, match="first="):
        interpolate_tentacles(positions, margin, brown.time, 3, 0.01, first=whole.shape[0])


def test_margin_point_walks_the_polyline():
    angles = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    square = np.stack([np.cos(angles), np.sin(angles), np.zeros(12)], axis=1)
    frame0 = local_frames(square[0], np.zeros(3), np.array([0.0, 0.0, 1.0]))
    points = margin_point(square, np.zeros(3), frame0, angles)
    np.testing.assert_allclose(points, square, atol=1e-12)
    mid = margin_point(square, np.zeros(3), frame0, np.array([np.pi / 12]))
    np.testing.assert_allclose(mid[0], 0.5 * (square[0] + square[1]), atol=1e-12)


def test_drawn_tentacles_keep_roots_on_margin_lengths_and_simulated_shapes(brown):
    scene = brown.scene
    factor = scene.tentacles.interpolation
    drawn = interpolate_result(brown)
    positions, margin = brown.tentacle_positions, brown.margin
    assert drawn.shape == (positions.shape[0], 6 * factor, 60, 3)
    # Simulated tentacles are drawn unchanged.
    np.testing.assert_array_equal(drawn[:, ::factor], positions)
    # Segment lengths restored.
    lengths = np.linalg.norm(np.diff(drawn, axis=2), axis=3)
    np.testing.assert_allclose(lengths, scene.tentacles.spacing, rtol=1e-9)
    # Every drawn root lies on the margin polyline (the pulsing, swimming, lobed margin).
    roots = drawn[:, :, 0]
    for f in range(0, positions.shape[0], 7):
        assert _distance_to_polyline(roots[f], margin[f]).max() < 1e-12
    # Roots are evenly spread around the rim, the ring wrapping from the last to the first.
    angle = np.unwrap(np.arctan2(roots[0, :, 1], roots[0, :, 0]))
    np.testing.assert_allclose(np.diff(angle), 2 * np.pi / (6 * factor), rtol=1e-6)


def _distance_to_polyline(points, polyline):
    """Distance (m) from each point (N, 3) to the closed polyline (R, 3): a slow oracle."""
    a, b = polyline, np.roll(polyline, -1, axis=0)
    ab = b - a
    t = np.einsum("nrk,rk->nr", points[:, None] - a[None], ab) / np.sum(ab * ab, axis=1)
    closest = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
    return np.linalg.norm(points[:, None] - closest, axis=2).min(axis=1)


def test_symmetric_tentacles_interpolate_to_rotated_copies(brown):
    # With identical simulated shapes in their local frames, every drawn tentacle has that
    # shape: blending in local frames neither pulls roots onto the chord nor shortens chains.
    single = brown.tentacle_positions[:, :1]
    angles = 2 * np.pi * np.arange(4) / 4
    rot = np.stack([[np.cos(a), -np.sin(a), 0, np.sin(a), np.cos(a), 0, 0, 0, 1] for a in angles])
    rot = rot.reshape(4, 3, 3)
    positions = np.einsum("tij,fpj->ftpi", rot, single[:, 0])
    margin = np.einsum("tij,fj->fti", rot, brown.tentacle_positions[:, 0, 0])
    drawn = interpolate_tentacles(positions, margin, brown.time, 8, 0.01)
    tip_height = drawn[:, :, -1, 2]
    np.testing.assert_allclose(tip_height - tip_height[:, :1], 0.0, atol=1e-9)
    tip_radius = np.linalg.norm(drawn[:, :, -1, :2], axis=2)
    reach = np.linalg.norm(drawn[:, :, 0, :2], axis=2)
    outward = tip_radius - reach
    np.testing.assert_allclose(outward - outward[:, :1], 0.0, atol=2e-3)


def test_no_banding_around_the_rim(brown):
    # DESIGN §2: cosine weights bunch drawn tentacles near the simulated ones. The RMS tip
    # distance (in the roots' local frames) between neighbouring drawn tentacles must vary by
    # less than 2x around the rim; without the lag it varies by about 20x.
    def spread(drawn):
        roots = drawn[:, :, 0]
        centre = brown.margin.mean(axis=1)
        frames = local_frames(roots, centre[:, None], np.array([0.0, 0.0, 1.0]))
        tips = np.einsum("ftij,ftj->fti", frames, drawn[:, :, -1] - roots)
        gaps = np.sqrt(np.mean(np.sum((tips - np.roll(tips, -1, axis=1)) ** 2, axis=2), axis=0))
        return gaps.max() / gaps.min()

    assert spread(interpolate_result(brown)) < 2.0
    assert spread(interpolate_result(brown, lag=0.0)) > 4.0


def test_lags_alternate_and_spare_the_simulated_tentacles():
    lags = interpolation_lags(3, 4, 0.2)
    np.testing.assert_allclose(lags, [0, 0.2, 0, 0.2] * 3)
    odd = interpolation_lags(2, 3, 0.2)
    np.testing.assert_allclose(odd, [0, 0.2, 0.1] * 2)
