"""Natural curl (issue 25): a tentacle's rest shape, docs/theory/tentacle.md §6."""

from __future__ import annotations

import math

import numpy as np
import pytest

import jellysim
from jellysim.errors import InputError
from jellysim.tentacle.contact import no_obstacle
from jellysim.tentacle.kernels import (
    Medium,
    advance_frame,
    bending_energy,
    bending_forces,
    curl_energy,
    curl_forces,
    rest_shape_positions,
)
from jellysim.tentacle.model import (
    build_chain_model,
    curl_normals,
    rest_second_differences,
)

DOWN = np.array([0.0, 0.0, -1.0])
OUTWARD = np.array([1.0, 0.0, 0.0])


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def total_energy(x, c, clamped, t, n, rest):
    work = np.empty((6, x.shape[0], 3))
    return bending_energy(x, c, clamped, t) + curl_energy(x, c, t, n, rest, work)


def total_forces(x, c, clamped, t, n, rest):
    straight, curl = np.empty_like(x), np.empty_like(x)
    bending_forces(x, c, clamped, t, straight)
    curl_forces(x, c, t, n, rest, np.empty((6, x.shape[0], 3)), curl)
    return straight + curl


@pytest.mark.parametrize("clamped", [True, False])
def test_curl_force_is_minus_gradient_of_energy(clamped):
    # A crumpled chain (segments of uneven length, up to ~100 degrees between neighbours, the
    # first segment far from the clamp direction) and an arbitrary rest shape: the frames'
    # dependence on the positions is in the force.
    rng = np.random.default_rng(11)
    particles, d, c = 14, 0.01, 3.7
    steps = DOWN * d + rng.normal(scale=0.6 * d, size=(particles - 1, 3))
    x = np.vstack([np.zeros(3), np.cumsum(steps, axis=0)])
    t = unit(np.array([0.3, -0.2, -1.0]))
    n = unit(np.cross(t, rng.normal(size=3)))
    rest = rest_second_differences(particles, d, 20.0, 45.0, 30.0, 0.7)
    rest += rng.normal(scale=0.2 * d, size=rest.shape) * (rest != 0.0)
    forces = total_forces(x, c, clamped, t, n, rest)
    h = 1e-7
    gradient = np.empty_like(x)
    for i in range(particles):
        for k in range(3):
            plus, minus = x.copy(), x.copy()
            plus[i, k] += h
            minus[i, k] -= h
            gradient[i, k] = (
                total_energy(plus, c, clamped, t, n, rest)
                - total_energy(minus, c, clamped, t, n, rest)
            ) / (2 * h)
    scale = np.abs(forces).max()
    assert scale > 1e-3  # the rest shape pulls hard on this chain
    # Central differences with h = 1e-7 m: truncation ~1e-14 relative, round-off ~1e-9.
    np.testing.assert_allclose(forces, -gradient, rtol=0, atol=1e-7 * scale)


def test_curl_forces_are_internal():
    # Minus the gradient of an energy that only depends on the shape relative to the root frame:
    # with the root included, the forces sum to zero (no net force from the rest shape).
    rng = np.random.default_rng(12)
    particles, d = 20, 0.01
    x = np.vstack([np.zeros(3), np.cumsum(DOWN * d + rng.normal(0, 0.3 * d, (19, 3)), axis=0)])
    rest = rest_second_differences(particles, d, 30.0, 30.0, 10.0, 0.0)
    out = np.empty_like(x)
    curl_forces(x, 2.0, DOWN, OUTWARD, rest, np.empty((6, particles, 3)), out)
    np.testing.assert_allclose(out.sum(axis=0), 0.0, atol=1e-14)


def test_planar_rest_shape_lies_on_its_circle():
    # theta = 2 asin(kappa d / 2): the nodes of a planar curl lie on the circle of radius 1/kappa
    # through the root, tangent to the clamp direction there, in the plane (t, n), curling
    # towards n.
    particles, d, kappa = 40, 0.01, 25.0
    rest = rest_second_differences(particles, d, kappa, kappa, 0.0, 0.0)
    x = np.empty((particles, 3))
    rest_shape_positions(np.zeros(3), DOWN, OUTWARD, rest, d, x)
    lengths = np.linalg.norm(np.diff(x, axis=0), axis=1)
    np.testing.assert_allclose(lengths, d, rtol=1e-14)
    np.testing.assert_allclose(x[:, 1], 0.0, atol=1e-15)
    # From particle 1 on (the clamp holds the first segment straight) every node lies on one
    # circle of radius 1/kappa: its centre from the first three, in the (x, z) plane.
    a, b, c = (x[i][[0, 2]] for i in (1, 2, 3))
    matrix = 2 * np.array([b - a, c - a])
    centre = np.linalg.solve(matrix, [b @ b - a @ a, c @ c - a @ a])
    np.testing.assert_allclose(
        np.linalg.norm(x[1:][:, [0, 2]] - centre, axis=1), 1.0 / kappa, rtol=1e-12
    )
    assert x[-1, 0] > 0.0  # curled outward


def test_helical_rest_shape_has_the_helix_radius_and_pitch():
    # Constant curvature k and torsion tau: a helix of radius k / (k^2 + tau^2) rising
    # 2 pi tau / (k^2 + tau^2) per turn, to O((k d)^2) at this spacing.
    k, tau = 40.0, 25.0
    per_turn = 64  # segments per turn of arc length 2 pi / sqrt(k^2 + tau^2)
    d = 2 * math.pi / math.sqrt(k * k + tau * tau) / per_turn
    particles = 2 + 4 * per_turn
    rest = rest_second_differences(particles, d, k, k, tau, 0.0)
    x = np.empty((particles, 3))
    rest_shape_positions(np.zeros(3), DOWN, OUTWARD, rest, d, x)
    radius = k / (k * k + tau * tau)
    rise = 2 * math.pi * tau / (k * k + tau * tau)
    # Over whole turns: the mean of the unit tangents lies along the axis, the mean point on it.
    turns = x[1 : 2 + 3 * per_turn]
    tangents = np.diff(turns, axis=0) / d
    axis = unit(tangents.mean(axis=0))
    assert (turns[-1] - turns[0]) @ axis == pytest.approx(3 * rise, rel=0.01)
    off = turns[:-1] - turns[:-1].mean(axis=0)
    off -= np.outer(off @ axis, axis)
    np.testing.assert_allclose(np.linalg.norm(off, axis=1), radius, rtol=0.01)


def still_chain(root: str, particles=60, d=0.01, kappa=30.0, tau=0.0, youngs_modulus=100.0):
    model = build_chain_model(particles, d, youngs_modulus, 1000.0, root=root)
    medium = Medium(1000.0, 1e-3, np.array([0.0, 0.0, -9.81]), 1000.0)  # neutrally buoyant
    rest = rest_second_differences(particles, d, kappa, 2 * kappa, tau, 0.3)[None].copy()
    x = np.empty((1, particles, 3))
    rest_shape_positions(np.zeros(3), DOWN, OUTWARD, rest[0], d, x[0])
    return model, medium, rest, x


@pytest.mark.parametrize("root", ["clamped", "pinned"])
@pytest.mark.parametrize("tau", [0.0, 20.0])
def test_unloaded_chain_keeps_its_rest_shape(root, tau):
    # No flow, neutral buoyancy, the root held still: the rest shape is the energy's minimum, a
    # fixed point of the step at any dt. Tolerance: 1e-9 m (1e-7 of the spacing) after 5 s at
    # the forced-tentacles preset's substep (1/120 s) and at one a hundred times longer.
    for dt, steps in ((1.0 / 120.0, 600), (0.5, 10)):
        model, medium, rest, x = still_chain(root, tau=tau)
        start = x.copy()
        v = np.zeros_like(x)
        zeros = np.zeros((steps, 1, 3))
        normals = zeros + OUTWARD
        diagnostics = np.zeros((1, 3))
        advance_frame(
            x, v, zeros, zeros, zeros + DOWN, normals, rest, zeros[:, :, None], model, medium, dt,
            diagnostics, np.zeros((1, 0, 3)), no_obstacle(),
        )  # fmt: skip
        assert diagnostics[0, 2] == -1
        assert np.abs(x - start).max() < 1e-9
        assert np.abs(v).max() < 1e-9


def test_a_straight_chain_coils_into_its_rest_shape():
    # Slack tentacles coil: released straight in still water, the chain settles into its rest
    # shape (drag takes the energy out). E = 0.1 MPa: the first mode's period is about 6 s
    # (at the presets' 100 Pa it is 3 minutes). After 30 s the bending energy has fallen to
    # below 1e-9 of its start and every particle is within 1e-6 m of its rest place (the
    # rest shape is approached exponentially: 1e-8 m measured).
    particles, d = 30, 0.01
    model, medium, rest, target = still_chain(
        "clamped", particles=particles, kappa=20.0, youngs_modulus=1e5
    )
    x = (np.arange(particles)[:, None] * d * DOWN)[None].copy()
    v = np.zeros_like(x)
    steps = 3600
    zeros = np.zeros((steps, 1, 3))
    diagnostics = np.zeros((1, 3))
    c = model.bending_stiffness
    energy_start = total_energy(x[0], c, True, DOWN, OUTWARD, rest[0])
    normals = zeros + OUTWARD
    advance_frame(
        x, v, zeros, zeros, zeros + DOWN, normals, rest, zeros[:, :, None], model, medium, 1 / 120,
        diagnostics, np.zeros((1, 0, 3)), no_obstacle(),
    )  # fmt: skip
    assert diagnostics[0, 2] == -1
    assert total_energy(x[0], c, True, DOWN, OUTWARD, rest[0]) < 1e-9 * energy_start
    assert np.abs(x - target).max() < 1e-6


def test_straight_scene_has_no_rest_shape():
    scene = jellysim.load_scene("forced-tentacles", {"duration": 0.1})
    sim = jellysim.Simulation(scene)
    assert not np.any(sim.rest_shape)
    curled = jellysim.load_scene(
        "forced-tentacles", {"duration": 0.1, "tentacles.rest_curvature": 0.0}
    )
    assert not np.any(jellysim.Simulation(curled).rest_shape)


def chord_after(speed: float, seconds: float = 3.0) -> float:
    """Root-to-tip distance over the length of one curled tentacle in a steady flow."""
    scene = jellysim.load_scene(
        "forced-tentacles",
        {
            "duration": seconds,
            "tentacles.count": 1,
            "tentacles.particles": 30,
            "tentacles.rest_curvature": 25.0,
            "tentacles.rest_torsion": 10.0,
            "root_motion.amplitude": 0.0,
            "flow.noise": 0.0,
            "flow.speed": speed,
        },
    )
    sim = jellysim.Simulation(scene)
    for _ in range(scene.frame_count - 1):
        sim.step_frame()
    x = sim.positions[0]
    return float(np.linalg.norm(x[-1] - x[0]) / (29 * 0.01))


def test_flow_straightens_a_curled_tentacle():
    chords = [chord_after(v) for v in (0.0, 0.02, 0.1, 0.4)]
    # At rest the helix (radius 3.4 cm, 1.15 turns of a 29 cm chain) keeps its chord (0.40 of the
    # length; measured 0.47, 0.97 and 1.00 at the faster flows); each faster
    # flow pulls it straighter, the fastest nearly straight.
    assert chords[0] < 0.5
    assert all(b > a + 0.02 for a, b in zip(chords, chords[1:], strict=False)), chords
    assert chords[-1] > 0.9


def test_curl_normals_are_the_outward_direction_across_the_root():
    directions = np.array([[[0.0, 0.0, -1.0], unit(np.array([1.0, 0.0, -1.0])), [1.0, 0, 0]]])
    outward = np.array([[[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]])
    axes = np.array([[0.0, 0.0, 1.0]])
    normals = curl_normals(directions, outward, axes)
    np.testing.assert_allclose(normals[0, 0], [1.0, 0.0, 0.0])
    np.testing.assert_allclose(normals[0, 1], unit(np.array([1.0, 0.0, 1.0])))
    np.testing.assert_allclose(normals[0, 2], [0.0, 0.0, 1.0])  # pointing outward: the axis
    np.testing.assert_allclose(np.sum(normals * directions, axis=2), 0.0, atol=1e-15)


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("tentacles.rest_curvature", 51.0),
        ("tentacles.rest_curvature_tip", 60.0),
        ("tentacles.rest_torsion", -55.0),
    ],
)
def test_too_tight_a_curl_is_refused_in_one_line(key, value):
    with pytest.raises(InputError) as error:
        jellysim.load_scene("forced-tentacles", {key: value})
    message = str(error.value)
    assert len(message.splitlines()) == 1
    assert message.startswith(f"{key} = ")
    assert "tentacles.spacing = 0.01" in message


def test_the_tightest_allowed_curl_is_accepted():
    scene = jellysim.load_scene(
        "forced-tentacles", {"tentacles.rest_curvature": 50.0, "tentacles.rest_torsion": -50.0}
    )
    assert scene.tentacles.rest_curvature == 50.0
    assert scene.tentacles.rest_torsion == -50.0
