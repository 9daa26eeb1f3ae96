"""Cosine interpolation of tentacles (paper §4.1.3; DESIGN §2 "Interpolation")."""

from types import SimpleNamespace

import numpy as np
import pytest

import jellysim
from jellysim.interpolation import (
    SHAPE_SPACES,
    cosine_weight,
    interpolate_result,
    interpolate_tentacles,
    interpolation_lags,
    local_frames,
    margin_point,
)
from jellysim.tentacle.kernels import rest_shape_positions
from jellysim.tentacle.model import rest_second_differences


@pytest.fixture(scope="module")
def brown(tmp_path_factory):
    # brown-jelly's marginal tentacles alone: one ring round the margin, no oral arms
    folder = tmp_path_factory.mktemp("brown")
    scene = jellysim.load_scene("brown-jelly", {"duration": 3.0}).group_scene(0)
    return jellysim.run(scene, folder)


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
    assert drawn.shape == (positions.shape[0], 6 * factor, scene.tentacles.particles, 3)
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


# Curled tentacles (issue 25): blending in Bishop curvatures, docs/theory/interpolation.md (I2-I4).

SPACING = 0.01
PARTICLES = 60
CURVATURE = 40.0  # 1/m: kappa d = 0.4, near the bound 0.5
TORSION = 15.0  # 1/m


def _coil(root, direction, outward, curl_angle):
    """A helix (P, 3) of the rest-shape model from ``root``, leaving along ``direction``."""
    rest = rest_second_differences(
        PARTICLES, SPACING, CURVATURE, CURVATURE, TORSION, np.radians(curl_angle)
    )
    normal = outward - (outward @ direction) * direction
    out = np.empty((PARTICLES, 3))
    rest_shape_positions(root, direction, normal / np.linalg.norm(normal), rest, SPACING, out)
    return out


def _coils_on_a_ring(curl_angles, frames=2):
    """Simulated coils (F, T, P, 3) of one rest shape, rotated about the bell axis (z) onto a
    ring of radius 0.1 m, with curl angles ``curl_angles`` (degrees, one per tentacle), and the
    ring as the margin (F, 72, 3)."""
    count = len(curl_angles)
    chains = []
    for k, angle in enumerate(curl_angles):
        phi = 2 * np.pi * k / count
        outward = np.array([np.cos(phi), np.sin(phi), 0.0])
        direction = np.array([0.3 * outward[0], 0.3 * outward[1], -1.0])
        chains.append(_coil(0.1 * outward, direction / np.linalg.norm(direction), outward, angle))
    ring = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    margin = 0.1 * np.stack([np.cos(ring), np.sin(ring), np.zeros(72)], axis=1)
    positions = np.broadcast_to(np.array(chains), (frames, count, PARTICLES, 3)).copy()
    return positions, np.broadcast_to(margin, (frames, 72, 3)).copy(), np.arange(frames) / 30


def _turning_angles(chains):
    """Angles (rad) between consecutive segments, (..., P - 2)."""
    e = np.diff(chains, axis=-2)
    t = e / np.linalg.norm(e, axis=-1, keepdims=True)
    return np.arccos(np.clip(np.sum(t[..., 1:, :] * t[..., :-1, :], axis=-1), -1.0, 1.0))


def _helix_radius_and_pitch(chains):
    """Radius and rise per turn (m) of discrete helices (..., P, 3) from their mean turning
    angle theta and dihedral angle psi between consecutive bending planes: kappa = theta / d,
    tau = psi / d, radius kappa / (kappa^2 + tau^2), pitch 2 pi tau / (kappa^2 + tau^2)."""
    e = np.diff(chains, axis=-2)
    b = np.cross(e[..., :-1, :], e[..., 1:, :])
    b /= np.linalg.norm(b, axis=-1, keepdims=True)
    psi = np.arccos(np.clip(np.sum(b[..., 1:, :] * b[..., :-1, :], axis=-1), -1.0, 1.0))
    kappa = _turning_angles(chains).mean(axis=-1) / SPACING
    tau = psi.mean(axis=-1) / SPACING
    return kappa / (kappa**2 + tau**2), 2 * np.pi * tau / (kappa**2 + tau**2)


@pytest.mark.parametrize("offset", [0.0, 90.0])
def test_curled_neighbours_draw_coils_of_the_same_radius_and_pitch(offset):
    # Two simulated coils of one rest shape, rotated about the bell axis; with offset 90 the
    # second one's curl is also turned a quarter turn about its root direction (its loops are
    # out of phase with the first's). Every drawn tentacle is the same coil.
    factor = 8
    positions, margin, times = _coils_on_a_ring([0.0, offset])
    drawn = interpolate_tentacles(
        positions, margin, times, factor, SPACING, shape_space="curvatures"
    )
    radius, pitch = _helix_radius_and_pitch(drawn)
    sim_radius, sim_pitch = _helix_radius_and_pitch(positions[0, 0])
    assert sim_radius == pytest.approx(CURVATURE / (CURVATURE**2 + TORSION**2), rel=0.01)
    np.testing.assert_allclose(radius, sim_radius, rtol=1e-6)
    np.testing.assert_allclose(pitch, sim_pitch, rtol=1e-6)
    # Segment lengths d, simulated tentacles exactly, roots on the ring.
    np.testing.assert_allclose(np.linalg.norm(np.diff(drawn, axis=2), axis=3), SPACING, rtol=1e-9)
    np.testing.assert_array_equal(drawn[:, ::factor], positions)
    np.testing.assert_allclose(np.linalg.norm(drawn[:, :, 0, :2], axis=2), 0.1, rtol=1e-3)
    if offset:
        # Blending positions, the out-of-phase loops partly cancel: the in-between coils are
        # squashed (pitch 10 % short) and turn more sharply than either simulated coil.
        old = interpolate_tentacles(positions, margin, times, factor, SPACING)
        _, old_pitch = _helix_radius_and_pitch(old)
        assert np.abs(old_pitch / sim_pitch - 1).max() > 0.05
        assert _turning_angles(old).max() > 1.2 * _turning_angles(positions).max()


@pytest.mark.parametrize("offset", [45.0, 135.0, 180.0])
def test_curled_blend_never_turns_sharper_than_the_simulated(offset):
    # No zigzag: at every node of every drawn tentacle the turning angle stays within the range
    # of the simulated tentacles' (the blended turning angle is a convex combination, I3), and
    # the dihedral between consecutive bending planes (the discrete torsion) as well, also
    # where the neighbours' loops point in opposite directions.
    positions, margin, times = _coils_on_a_ring([0.0, offset, 2 * offset, 3 * offset])
    drawn = interpolate_tentacles(positions, margin, times, 10, SPACING, shape_space="curvatures")
    sim = _turning_angles(positions)
    turning = _turning_angles(drawn)
    assert turning.max() <= sim.max() * (1 + 1e-9)
    # Where two neighbours bend in opposite directions the one between them straightens
    # (there the bending plane is undefined); elsewhere the plane turns no faster than theirs.
    e = np.diff(drawn, axis=-2)
    b = np.cross(e[..., :-1, :], e[..., 1:, :])
    size = np.linalg.norm(b, axis=-1)
    bent = (size[..., 1:] > 1e-3 * SPACING**2) & (size[..., :-1] > 1e-3 * SPACING**2)
    b /= np.maximum(size, 1e-300)[..., None]
    dihedral = np.arccos(np.clip(np.sum(b[..., 1:, :] * b[..., :-1, :], axis=-1), -1, 1))
    assert bent.mean() >= 0.85
    assert dihedral[bent].max() < 2 * TORSION * SPACING


def test_curvature_coordinates_rebuild_the_chain():
    # decode(encode(x)) = x: a crumpled chain, a coil and a straight one, so that a drawn
    # tentacle at t = 0 coincides with the simulated one before it is replaced by it.
    rng = np.random.default_rng(4)
    steps = rng.normal(size=(PARTICLES - 1, 3)) + [0.0, 0.0, -2.0]
    crumpled = np.vstack([np.zeros(3), np.cumsum(steps, axis=0)])
    crumpled = SPACING * crumpled / np.linalg.norm(steps, axis=1).mean()
    segments = np.diff(crumpled, axis=0)
    segments *= SPACING / np.linalg.norm(segments, axis=1, keepdims=True)
    crumpled = np.vstack([np.zeros(3), np.cumsum(segments, axis=0)])
    coil = _coil(np.zeros(3), np.array([0.0, 0.6, -0.8]), np.array([1.0, 0.0, 0.0]), 30.0)
    straight = np.outer(np.arange(PARTICLES), [0.0, 0.0, -SPACING])
    shapes = np.stack([crumpled, coil, straight])
    space = SHAPE_SPACES["curvatures"]
    np.testing.assert_allclose(space.decode(space.encode(shapes), SPACING), shapes, atol=1e-12)


def test_a_curled_scene_blends_curvatures_and_a_straight_one_positions(brown):
    # The straight preset is drawn exactly as before (blended positions, bit for bit); the same
    # frames under a scene with a rest curvature are blended in curvatures.
    positions, margin = brown.tentacle_positions, brown.margin
    lag = 0.25 * brown.scene.bell.period
    straight = interpolate_tentacles(
        positions, margin, brown.time, 3, brown.scene.tentacles.spacing, lag_spread=lag
    )
    straight_scene = jellysim.load_scene(
        brown.scene,
        {"tentacles.rest_curvature": 0.0, "tentacles.rest_curvature_tip": 0.0},
    )
    as_straight = SimpleNamespace(scene=straight_scene, time=brown.time, read=brown.read)
    np.testing.assert_array_equal(interpolate_result(as_straight, 3), straight)
    curled_scene = jellysim.load_scene(brown.scene, {"tentacles.rest_curvature": 20.0})
    curled = SimpleNamespace(scene=curled_scene, time=brown.time, read=brown.read)
    expected = interpolate_tentacles(
        positions,
        margin,
        brown.time,
        3,
        brown.scene.tentacles.spacing,
        lag_spread=lag,
        shape_space="curvatures",
    )
    np.testing.assert_array_equal(interpolate_result(curled, 3), expected)
    assert np.abs(expected - straight).max() > 1e-6
    # The viewer's windows of frames are slices of the whole here too.
    window = interpolate_result(curled, 3, frames=(17, 40))
    np.testing.assert_allclose(window, expected[17:40], rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="shape_space"):
        interpolate_tentacles(positions, margin, brown.time, 3, 0.01, shape_space="angles")
