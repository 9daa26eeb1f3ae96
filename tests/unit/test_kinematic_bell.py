"""The kinematic bell (docs/theory/bell.md, Eq. B1-B6): waveform, roots, swimming and mesh."""

import numpy as np
import pytest

import jellysim
from jellysim.bell import make_root_driver
from jellysim.bell.kinematic import bell_faces, contraction_waveform, smoothstep

BELL = {
    "bell.model": "kinematic",
    "bell.radius": 0.15,
    "bell.height": 0.1,
    "bell.contraction": 0.2,
    "bell.period": 1.0,
    "bell.swim_speed": 0.3,
    "bell.lobes": 0,
    "bell.jet_fraction": 0.3,
}


def _bell(**overrides):
    # brown-jelly's marginal tentacles alone: every root on the margin
    scene = jellysim.load_scene("brown-jelly", {**BELL, **overrides}).group_scene(0)
    return make_root_driver(scene)


@pytest.mark.parametrize("waveform", ["jet", "sine"])
def test_waveform_is_a_c2_cycle_from_rest_to_full_contraction(waveform):
    phase = np.linspace(0.0, 1.0, 200001)
    c, slope = contraction_waveform(phase, waveform, 0.3)
    assert c[0] == pytest.approx(0.0, abs=1e-15) and c[-1] == pytest.approx(0.0, abs=1e-12)
    assert c.max() == pytest.approx(1.0, abs=1e-9) and c.min() >= 0.0
    # The derivative is the derivative: central differences, O(h^2).
    h = phase[1] - phase[0]
    np.testing.assert_allclose(np.gradient(c, h)[1:-1], slope[1:-1], atol=1e-6)
    # C2: the slope changes by O(h) per sample everywhere (no kink at the phase joins) and it
    # is periodic (0 at both ends of the cycle).
    assert np.abs(np.diff(slope)).max() < 1e-3
    assert slope[0] == pytest.approx(slope[-1], abs=1e-9)


def test_jet_contracts_fast_and_relaxes_slowly():
    phase = np.linspace(0.0, 1.0, 10001)
    c, slope = contraction_waveform(phase, "jet", 0.3)
    assert phase[np.argmax(c)] == pytest.approx(0.3, abs=1e-4)
    assert slope.max() > 2.0 * -slope.min()  # contracting at 0.3, relaxing over 0.7


def test_quintic_smoothstep_as_data():
    x = np.array([0.0, 0.5, 1.0])
    value, slope = smoothstep(x)
    np.testing.assert_allclose(value, [0.0, 0.5, 1.0], atol=1e-15)
    np.testing.assert_allclose(slope, [0.0, 1.875, 0.0], atol=1e-15)


@pytest.mark.parametrize("lobes", [0, 8])
def test_root_velocities_are_the_c1_derivative_of_the_positions(lobes):
    bell = _bell(**{"bell.lobes": lobes, "bell.lobe_depth": 0.1})
    t = np.linspace(0.0, 2.0, 40001)
    positions, velocities, directions = bell.roots(t)
    h = t[1] - t[0]
    np.testing.assert_allclose(np.gradient(positions, h, axis=0)[1:-1], velocities[1:-1], atol=2e-6)
    # C1: velocities change by O(h) per sample, also across the jet/relax joins.
    assert np.abs(np.diff(velocities, axis=0)).max() < 60.0 * h
    np.testing.assert_allclose(np.linalg.norm(directions, axis=2), 1.0, atol=1e-14)


def test_margin_loses_the_contraction_fraction_of_its_radius():
    bell = _bell()
    t = np.linspace(0.0, 1.0, 1001)
    q, _, _, _ = bell.motion(t)
    positions, _, _ = bell.roots(t)
    radius = np.linalg.norm(positions[..., :2], axis=2)
    np.testing.assert_allclose(
        radius, np.broadcast_to(0.15 * (1.0 - q)[:, None], radius.shape), rtol=1e-14
    )
    assert radius.min() == pytest.approx(0.15 * (1.0 - 0.2), rel=1e-6)
    margin = bell.margin(0.3)  # the jet's end: full contraction
    np.testing.assert_allclose(np.linalg.norm(margin[:, :2], axis=1), 0.12, rtol=1e-12)


def test_roots_are_margin_vertices_and_the_margin_is_the_outer_rim_of_the_mesh():
    bell = _bell(**{"bell.lobes": 32, "bell.lobe_depth": 0.04})
    for time in (0.0, 0.2, 0.7):
        margin = bell.margin(time)
        roots, _, _ = bell.roots(np.array([time]))
        step = margin.shape[0] // roots.shape[1]
        np.testing.assert_allclose(margin[::step], roots[0], atol=1e-15)
        vertices = bell.surface(time)
        lowest = np.isclose(vertices[:, 2], vertices[:, 2].min(), atol=1e-12)
        assert lowest.sum() == margin.shape[0]  # the margin is the mesh's lowest ring
        np.testing.assert_allclose(np.sort(vertices[lowest, 0]), np.sort(margin[:, 0]))


def test_clamp_direction_hangs_at_rest_and_turns_inwards_with_the_wall():
    bell = _bell(**{"bell.lobes": 32, "bell.lobe_depth": 0.04})
    _, _, at_rest = bell.roots(np.array([0.0]))
    np.testing.assert_allclose(at_rest[0], [[0.0, 0.0, -1.0]] * 6, atol=1e-15)
    positions, _, contracted = bell.roots(np.array([0.3]))
    radial = positions[0, :, :2] / np.linalg.norm(positions[0, :, :2], axis=1, keepdims=True)
    inward = -np.sum(contracted[0, :, :2] * radial, axis=1)
    assert np.all(inward > 0.1)  # about 15 degrees at 20 % contraction


def test_the_bell_swims_at_its_mean_speed_fast_while_jetting_and_coasting_after():
    bell = _bell(**{"bell.speed_variation": 0.8})
    t = np.linspace(0.0, 3.0, 30001)
    _, _, z, u = bell.motion(t)
    assert z[-1] - z[0] == pytest.approx(0.3 * 3.0, rel=1e-12)  # U per unit time, whole cycles
    np.testing.assert_allclose(np.gradient(z, t[1] - t[0])[1:-1], u[1:-1], atol=1e-6)
    assert u.min() == pytest.approx(0.2 * 0.3, rel=1e-6)  # (1 - variation) U
    phase = np.mod(t, 1.0)
    assert u[phase < 0.3].mean() > 2.0 * u[phase >= 0.3].mean()
    np.testing.assert_allclose(bell.bell_velocity(t)[:, 2], u)


def test_zero_contraction_holds_the_bell_still():
    bell = _bell(**{"bell.contraction": 0.0, "bell.swim_speed": 0.0})
    t = np.linspace(0.0, 2.0, 11)
    positions, velocities, directions = bell.roots(t)
    np.testing.assert_array_equal(positions, np.broadcast_to(positions[:1], positions.shape))
    np.testing.assert_array_equal(velocities, 0.0)
    np.testing.assert_allclose(directions, np.broadcast_to([0.0, 0.0, -1.0], directions.shape))
    np.testing.assert_array_equal(bell.surface(0.0), bell.surface(1.3))
    assert bell.forcing().period == 0.0


def test_swimming_needs_a_pulse():
    with pytest.raises(jellysim.InputError, match="bell.swim_speed"):
        jellysim.load_scene("brown-jelly", {"bell.contraction": 0.0})


def test_forced_root_motion_is_refused_with_a_kinematic_bell():
    with pytest.raises(jellysim.InputError, match="root_motion.amplitude"):
        jellysim.load_scene("brown-jelly", {"root_motion.amplitude": 0.01})


def test_forcing_scales_bound_the_sampled_motion():
    bell = _bell()
    t = np.linspace(0.0, 1.0, 100001)
    _, velocities, _ = bell.roots(t)
    relative = velocities - np.array([0.0, 0.0, 0.3])  # about the bell's mean motion
    speed = np.linalg.norm(relative, axis=2).max()
    acceleration = np.linalg.norm(np.diff(velocities, axis=0), axis=2).max() / (t[1] - t[0])
    forcing = bell.forcing()
    assert 0.5 * forcing.speed < speed <= forcing.speed * (1 + 1e-9)
    assert 0.5 * forcing.acceleration < acceleration <= forcing.acceleration * (1 + 1e-3)


def test_mesh_is_a_closed_outward_shell_of_the_profiles_volume():
    bell = _bell(**{"bell.thickness": 0.3})
    faces = bell.faces
    vertices = bell.surface(0.0)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    directed = set(map(tuple, edges))
    assert len(directed) == len(edges)  # no edge twice in one direction: consistent orientation
    assert all((b, a) in directed for a, b in directed)  # every edge shared: closed
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    # Oracle: volumes of revolution of the outer and inner meridians (Eq. B1), by quadrature.
    s = np.linspace(0.0, 1.0, 20001)
    angle = 0.5 * np.pi * s
    scale = 1.0 - 0.3 * (1.0 - s**2)
    outer = np.trapezoid(np.pi * (0.15 * np.sin(angle)) ** 2 * 0.1 * 0.5 * np.pi * np.sin(angle), s)
    rho_in, z_in = scale * 0.15 * np.sin(angle), scale * 0.1 * np.cos(angle)
    inner = np.trapezoid(np.pi * rho_in**2 * -np.gradient(z_in, s), s)
    assert outer == pytest.approx(2.0 / 3.0 * np.pi * 0.15**2 * 0.1, rel=1e-6)  # half-ellipsoid
    assert volume == pytest.approx(outer - inner, rel=0.03)


def test_faces_index_every_vertex():
    faces = bell_faces(12, rings=4)
    assert faces.min() == 0 and faces.max() == 1 + 7 * 12
    assert np.unique(faces).size == 2 + 7 * 12


def test_inside_marks_the_dome_and_its_cavity_only():
    bell = _bell()
    z = float(bell.motion(np.array([0.4]))[2][0])
    points = np.array(
        [
            [0.0, 0.0, z + 0.05],  # under the apex
            [0.1, 0.0, z + 0.01],  # in the cavity near the margin
            [0.0, 0.0, z - 0.01],  # below the margin plane
            [0.3, 0.0, z + 0.05],  # beside the bell
            [0.0, 0.0, z + 0.3],  # above it
        ]
    )
    np.testing.assert_array_equal(bell.inside(points, 0.4), [True, True, False, False, False])
