"""The mass-spring bell (paper §4.2.1-4.2.4, docs/theory/soft-bell.md Eq. B7-B12) without the fluid
stepping: shape, springs, muscle (the body), the recorded margin and roots, the skinned surface."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scenes

import jellysim
from jellysim.bell.skin import BellSkin
from jellysim.bell.soft import CIRCUMFERENTIAL, SPRING_SAFETY, SoftBell
from jellysim.bell.swimming import phase_lag
from jellysim.coupling.bell_in_fluid import BellInFluid
from jellysim.coupling.margin import RecordedMargin, depth_inside
from jellysim.fluid.geometry import FLUID
from jellysim.fluid.setup import fluid_particles

# A bell 8 l0 wide and 5 l0 tall in a 22 x 22 x 15 l0 tank: resolved, yet small.
SMALL = {**scenes.SMALL_MOON, "bell.radius": 2.0}
L0 = float(scenes.SMALL_MOON["fluid.spacing"])  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def scene() -> jellysim.Scene:
    # The paper's ten tentacles alone (its oral arms: tests/integration/test_soft_bell_groups.py)
    return jellysim.load_scene(scenes.one_table("moon-jelly"), SMALL)


@pytest.fixture(scope="module")
def coupled(scene: jellysim.Scene) -> BellInFluid:
    return BellInFluid(scene)


@pytest.fixture(scope="module")
def bell(coupled: BellInFluid) -> SoftBell:
    return coupled.body


@pytest.fixture(scope="module")
def margin(coupled: BellInFluid) -> RecordedMargin:
    return coupled.margin


@pytest.fixture(scope="module")
def skin(coupled: BellInFluid) -> BellSkin:
    return coupled.skin


def test_particles_are_lattice_cells_of_the_shell(scene: jellysim.Scene, bell: SoftBell) -> None:
    l0 = scene.fluid.spacing
    cells = bell.rest / l0 - 0.5
    assert np.allclose(cells, np.round(cells), atol=1e-9)  # on the fluid's cell-centred lattice
    positions, kinds, _ = fluid_particles(scene)
    carved = (kinds == FLUID) & bell.shape.shell(positions)
    np.testing.assert_array_equal(positions[carved], bell.rest)
    # Shell volume between the half-ellipsoids (2/3 pi (R^2 H - r^2 h)) over l0^3, within 15 %.
    b = scene.bell
    w = b.thickness * b.height
    volume = 2.0 / 3.0 * math.pi * (b.radius**2 * b.height - (b.radius - w) ** 2 * (b.height - w))
    assert len(bell.rest) == pytest.approx(volume / l0**3, rel=0.15)
    relative = bell.rest - bell.shape.centre
    assert relative[:, 2].min() == pytest.approx(0.5 * l0)  # the margin layer on the plane


def test_springs_join_every_close_pair_once(scene: jellysim.Scene, bell: SoftBell) -> None:
    reach = scene.bell.spring_radius * scene.fluid.spacing
    d = np.linalg.norm(bell.rest[:, None] - bell.rest[None], axis=2)
    close = np.argwhere(np.triu(d < reach, k=1))
    np.testing.assert_array_equal(bell.springs.pairs, close)  # brute force, same order
    np.testing.assert_allclose(bell.springs.rest_length, d[close[:, 0], close[:, 1]])


def test_muscle_springs_run_around_the_margin_band(scene: jellysim.Scene, bell: SoftBell) -> None:
    s = bell.springs
    ends = bell.rest[s.pairs[s.muscle]]
    assert s.muscle.sum() > 0
    band = scene.bell.muscle_band * scene.bell.height
    assert np.all(ends[..., 2] - bell.shape.centre[2] < band)
    direction = ends[:, 1] - ends[:, 0]
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    mid = ends.mean(axis=1) - bell.shape.centre
    theta = np.stack([-mid[:, 1], mid[:, 0], np.zeros(len(mid))], axis=1)
    theta /= np.linalg.norm(theta, axis=1)[:, None]
    assert np.all(np.abs(np.einsum("ij,ij->i", direction, theta)) >= CIRCUMFERENTIAL - 1e-12)


def _reference_forces(
    bell: SoftBell, positions: np.ndarray, time: float, b: jellysim.Scene
) -> np.ndarray:
    """Paper Eq. 6 summed pair by pair, with the muscle's rest length and stiffness (Eq. B9,
    tapered by Eq. B9t as the scene ``b`` says)."""
    a = bell.activation(time)
    band = b.bell.muscle_band * b.bell.height
    forces = np.zeros_like(positions)
    for (i, j), rest, muscle in zip(
        bell.springs.pairs, bell.springs.rest_length, bell.springs.muscle, strict=True
    ):
        height = 0.5 * (bell.rest[i, 2] + bell.rest[j, 2]) - bell.shape.centre[2]
        w = min(max(1.0 - b.bell.muscle_taper * height / band, 0.0), 1.0)
        k = bell.stiffness * (1.0 + (bell.muscle_stiffening - 1.0) * a * w if muscle else 1.0)
        length0 = rest * (1.0 - bell.muscle_ratio * a * w if muscle else 1.0)
        r = positions[i] - positions[j]
        force = -k * (np.linalg.norm(r) - length0) * r / np.linalg.norm(r)
        forces[i] += force
        forces[j] -= force
    return forces


@pytest.mark.parametrize("time", [0.0, 0.3, 0.6, 1.4])
def test_spring_forces_match_hookes_law_and_sum_to_zero(
    scene: jellysim.Scene, bell: SoftBell, time: float
) -> None:
    rng = np.random.default_rng(3)
    positions = bell.rest + 0.1 * L0 * rng.standard_normal(bell.rest.shape)
    forces = np.empty_like(positions)
    bell.spring_forces(positions, time, forces)
    assert scene.bell.muscle_taper > 0.0  # the preset's tapered muscle (Eq. B9t)
    expected = _reference_forces(bell, positions, time, scene)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(forces, expected, atol=1e-12 * scale)
    # Newton's third law: no net force and no net torque from internal springs.
    np.testing.assert_allclose(forces.sum(axis=0), 0.0, atol=1e-10 * scale)
    torque = np.cross(positions, forces).sum(axis=0)
    np.testing.assert_allclose(torque, 0.0, atol=1e-9 * scale * np.abs(positions).max())


def test_a_tapered_muscle_contracts_most_at_the_margin() -> None:
    """Eq. B9t: each muscle spring's rest length at full activation is L0 (1 - ratio w), its
    stiffness k (1 + (stiffening - 1) w), w = 1 - taper h / (band H) from its mid-point's height;
    the same springs as the untapered bell (taper 0 is B9 itself: the regression references)."""
    band = {**SMALL, "bell.muscle_band": 0.6, "bell.muscle_taper": 0.0}  # three rings in the band
    plain_scene = jellysim.load_scene(scenes.one_table("moon-jelly"), band)
    b = plain_scene.bell
    tapered = BellInFluid(
        jellysim.load_scene(scenes.one_table("moon-jelly"), {**band, "bell.muscle_taper": 1.0})
    ).body
    plain = BellInFluid(plain_scene).body
    np.testing.assert_array_equal(tapered.springs.pairs, plain.springs.pairs)
    np.testing.assert_array_equal(tapered.springs.muscle, plain.springs.muscle)
    peak = b.jet_fraction * b.period  # a = 1
    assert tapered.activation(peak) == pytest.approx(1.0)
    positions = tapered.rest.copy()
    forces = np.empty_like(positions)
    tapered.spring_forces(positions, peak, forces)
    s = tapered.springs
    height = (tapered.rest[s.pairs].mean(axis=1) - tapered.shape.centre)[:, 2]
    w = np.clip(1.0 - height / (b.muscle_band * b.height), 0.0, 1.0)
    a = tapered.activation(peak)
    muscle = s.muscle
    np.testing.assert_allclose(
        tapered._rest_length[muscle],
        s.rest_length[muscle] * (1.0 - b.muscle_ratio * a * w[muscle]),
        rtol=1e-14,
    )
    np.testing.assert_allclose(
        tapered._stiffness[muscle],
        b.spring_stiffness * (1.0 + (b.muscle_stiffening - 1.0) * a * w[muscle]),
        rtol=1e-14,
    )
    np.testing.assert_array_equal(tapered._rest_length[~muscle], s.rest_length[~muscle])
    # The lowest rings shorten by nearly the full ratio, the band's top ones by little.
    low, high = w[muscle].max(), w[muscle].min()
    assert low > 0.8 and high < 0.2, (low, high)
    # The margin draws in less overall than with the whole band alike, never more.
    plain_forces = np.empty_like(positions)
    plain.spring_forces(positions, peak, plain_forces)
    assert np.abs(forces).max() < np.abs(plain_forces).max()


def test_relaxed_bell_feels_no_spring_force(bell: SoftBell) -> None:
    forces = np.empty_like(bell.rest)
    bell.spring_forces(bell.rest, 0.0, forces)  # activation 0 at t = 0
    assert np.abs(forces).max() == 0.0


def test_muscle_cycle_is_periodic_continuous_and_full(bell: SoftBell) -> None:
    period = bell.period
    times = np.linspace(0.0, 3.0 * period, 3001)
    a = np.array([bell.activation(t) for t in times])
    assert a[0] == 0.0 and a.min() >= 0.0 and a.max() == pytest.approx(1.0, abs=1e-4)
    later = np.array([bell.activation(t + period) for t in times])
    np.testing.assert_allclose(later, a, atol=1e-12)  # periodic
    step = times[1] - times[0]
    # C1 waveform: the largest jump between samples is bounded by the peak slope times the step.
    assert np.abs(np.diff(a)).max() < 2.0 / (bell.jet_fraction * period) * step
    assert bell.activation(bell.jet_fraction * period) == pytest.approx(1.0)


def test_roots_sit_on_the_margin_and_hang_down_at_rest(
    scene: jellysim.Scene, bell: SoftBell, margin: RecordedMargin, skin: BellSkin
) -> None:
    assert scene.bell.root_placement == "edge"  # the default
    roots, velocities, directions = margin.roots(np.array([0.0]))
    assert roots.shape == (1, scene.tentacles.count, 3)
    np.testing.assert_allclose(velocities, 0.0)
    np.testing.assert_allclose(directions[0], np.tile([0.0, 0.0, -1.0], (len(roots[0]), 1)),
                               atol=1e-12)  # fmt: skip
    relative = roots[0] - bell.shape.centre
    angles = np.mod(np.arctan2(relative[:, 1], relative[:, 0]), 2 * np.pi)
    expected = 2 * np.pi * np.arange(scene.tentacles.count) / scene.tentacles.count
    # The Gaussian means of square-lattice cells sit within a hundredth of a radian of the angle.
    np.testing.assert_allclose(np.angle(np.exp(1j * (angles - expected))), 0.0, atol=0.01)
    # Each root is its margin sample carried down and out (Eq. B10b) onto the drawn margin's
    # outer edge, the outer ellipsoid's lowest ring at the bell's radius.
    samples = margin.margin(0.0)[:: margin.root_every]
    drop = margin.drop[:: margin.root_every]
    reach = margin.reach[:: margin.root_every]
    w = scene.bell.thickness * scene.bell.height
    assert np.all((drop > 0.0) & (drop < L0))
    assert np.all((reach > 0.0) & (reach < w + L0))
    radial = relative / np.hypot(relative[:, 0], relative[:, 1])[:, None]
    radial[:, 2] = 0.0
    np.testing.assert_allclose(
        roots[0], samples - drop[:, None] * [0.0, 0.0, 1.0] + reach[:, None] * radial, atol=1e-12
    )
    rim = skin.rim()[:: margin.root_every]
    # (the radial reach from a sample a hundredth of a radian off its meridian: rho within 1e-4)
    np.testing.assert_allclose(np.hypot(relative[:, 0], relative[:, 1]), scene.bell.radius,
                               rtol=1e-4)  # fmt: skip
    np.testing.assert_allclose(roots[0][:, 2], rim[:, 2], atol=1e-12)


def test_edge_roots_hang_from_the_drawn_margins_outer_edge(
    margin: RecordedMargin, skin: BellSkin
) -> None:
    """Nothing of the drawn bell lies below an edge root or outside it: a point a little below
    the root, or out and below, is outside the tissue; the wall begins just in and up from it."""
    roots = margin.roots(np.array([0.0]))[0][0]
    vertices, faces = skin.rest_surface, skin.faces
    radial = roots - skin.rest_surface[0]
    radial[:, 2] = 0.0
    radial /= np.linalg.norm(radial, axis=1)[:, None]
    down = np.array([0.0, 0.0, 1.0])
    for offset in (-0.01 * L0 * down, 0.01 * L0 * (radial - down), -L0 * down):
        np.testing.assert_array_equal(depth_inside(roots + offset, vertices, faces), 0.0)
    assert np.all(depth_inside(roots + 0.1 * L0 * (down - 2.0 * radial), vertices, faces) > 0.0)


def test_surface_roots_start_on_the_underside_of_the_drawn_bell() -> None:
    """``"surface"`` (the default before "edge"): each root is its margin sample dropped along
    -z onto the underside of the drawn surface. A point just above a root is in the bell's
    tissue, the root itself and a point just below it are not."""
    scene = jellysim.load_scene(
        scenes.one_table("moon-jelly"), {**SMALL, "bell.root_placement": "surface"}
    )
    coupled = BellInFluid(scene)
    margin, skin = coupled.margin, coupled.skin
    roots = margin.roots(np.array([0.0]))[0][0]
    samples = margin.margin(0.0)[:: margin.root_every]
    drop = margin.drop[:: margin.root_every]
    assert np.all((drop > 0.0) & (drop < L0))
    np.testing.assert_array_equal(margin.reach, 0.0)
    np.testing.assert_allclose(roots, samples - drop[:, None] * [0.0, 0.0, 1.0], atol=1e-15)
    up = np.array([0.0, 0.0, 1e-6 * L0])
    vertices, faces = skin.rest_surface, skin.faces
    assert np.all(depth_inside(roots + 100 * up, vertices, faces) > 0.0)
    np.testing.assert_allclose(depth_inside(roots + up, vertices, faces), 1e-6 * L0, rtol=1e-3)
    np.testing.assert_array_equal(depth_inside(roots - up, vertices, faces), 0.0)


def test_edge_root_velocity_carries_the_walls_turn(coupled: BellInFluid) -> None:
    """Eq. B10b: the recorded root velocity is the derivative of the recorded root position
    along a motion of the bell's particles, the offsets' turn with the wall included. The
    motion turns every meridian's section about a horizontal circle (an axisymmetric field,
    as a contraction's inward turn of the margin) and drifts the bell."""
    bell, margin = coupled.body, coupled.margin
    rest = bell.rest
    centre = bell.shape.centre
    relative = rest - centre
    rho = np.hypot(relative[:, 0], relative[:, 1])
    radial = np.zeros_like(rest)
    radial[:, :2] = relative[:, :2] / rho[:, None]
    pivot_rho, pivot_z = 0.5 * bell.shape.radius, 0.5 * bell.shape.height
    turn = 0.8  # rad/s: the margin swings inward and up about the circle
    field = (-turn * (relative[:, 2] - pivot_z))[:, None] * radial
    field[:, 2] += turn * (rho - pivot_rho)
    field += [0.01, -0.02, 0.05]
    eps = 1e-6
    found = []
    for frame, sign in ((1, 1.0), (2, -1.0), (3, 0.0)):
        margin.record(frame, rest + sign * eps * field, field)
        found.append(margin.records[frame])
    derivative = (found[0].roots - found[1].roots) / (2 * eps)
    recorded = found[2].velocities
    scale = np.abs(derivative).max()
    np.testing.assert_allclose(recorded, derivative, atol=2e-3 * scale)
    # The turn's term matters here: the margin samples' own velocity is well off the derivative.
    sample_velocity = (margin._margin_weights @ field)[:: margin.root_every]
    assert np.abs(sample_velocity - derivative).max() > 0.05 * scale
    margin.restart(0, rest, np.zeros_like(rest))


@pytest.fixture(scope="module")
def armed() -> dict[str, BellInFluid]:
    """The small bell with the moon-jelly preset's four oral arms at the mouth, their roots
    carried from the drawn underside's centre (the default) and from the margin plane."""
    return {
        anchor: BellInFluid(jellysim.load_scene("moon-jelly", {**SMALL, "bell.arm_anchor": anchor}))
        for anchor in ("subumbrella", "margin")
    }


def _flattened(coupled: BellInFluid) -> tuple[np.ndarray, np.ndarray]:
    """The bell's particles pressed to a fifth of their height with the margin lifted to the
    middle of the squashed wall near the axis (moon-jelly's bell against the water's surface,
    docs/figures.md note 8, in caricature), and a motion field (m/s) of that kind."""
    shape, rest = coupled.body.shape, coupled.body.rest
    relative = rest - shape.centre
    rho2 = (relative[:, 0] ** 2 + relative[:, 1] ** 2) / shape.radius**2
    lift = 0.2 * (shape.height - 0.5 * shape.wall)
    field = np.zeros_like(rest)
    field[:, 2] = -0.8 * relative[:, 2] + lift * rho2
    return rest + field, field


def test_oral_arms_hang_from_the_drawn_undersides_centre(armed: dict[str, BellInFluid]) -> None:
    """Eq. B10c: at rest the arms' roots sit on their circle in the margin plane, the anchor
    or none; as the bell deforms they keep their stalk below the drawn underside's centre
    (the inner apex), moving at its velocity. Pressed flat with its margin lifted, a bell's
    margin plane lies in its own wall over the axis: roots on that plane are in the drawn
    tissue, roots on the stalk are below it."""
    stalked, plane = armed["subumbrella"], armed["margin"]
    mouth = stalked.margin.layout.mouth
    assert mouth.sum() == 4
    at_rest = [c.margin.roots(np.array([0.0]))[0][0][mouth] for c in (stalked, plane)]
    np.testing.assert_allclose(at_rest[0], at_rest[1], rtol=0, atol=1e-12)
    centre = stalked.margin.rest_margin.mean(axis=0)
    np.testing.assert_allclose(at_rest[1][:, 2], centre[2], atol=1e-12)
    skin = stalked.skin
    vertices, faces = skin.rest_surface, skin.faces
    stalk = skin.rest_surface[-1] - at_rest[0]  # up to the inner apex
    shape = stalked.body.shape
    inner_apex = shape.centre[2] + shape.height - shape.wall
    np.testing.assert_allclose(stalk[:, 2], inner_apex - centre[2], atol=1e-12)
    positions, field = _flattened(stalked)
    for c in (stalked, plane):
        c.margin.record(1, positions, field)
    roots = [c.margin.records[1].roots[mouth] for c in (stalked, plane)]
    apex = skin.surface(positions)[-1]
    np.testing.assert_allclose(roots[0] + stalk, np.broadcast_to(apex, roots[0].shape), atol=1e-12)
    np.testing.assert_allclose(
        stalked.margin.records[1].velocities[mouth],
        np.broadcast_to(skin.surface(skin.rest + field)[-1] - skin.rest_surface[-1], (4, 3)),
        atol=1e-12,
    )  # the field is the motion's velocity: the apex's is the skin's displacement under it
    drawn = skin.surface(positions)
    assert np.all(depth_inside(roots[1], drawn, faces) > 0.0)  # the margin plane: in the wall
    np.testing.assert_array_equal(depth_inside(roots[0], drawn, faces), 0.0)
    # ... and under the tissue that is straight above them
    above = np.linalg.norm((drawn - roots[0][:, None])[..., :2], axis=2) < 0.5 * L0
    for k in range(4):
        assert drawn[above[k], 2].min() > roots[0][k, 2]
    np.testing.assert_array_equal(depth_inside(at_rest[0], vertices, faces), 0.0)
    for c in (stalked, plane):
        c.margin.restart(0, c.body.rest, np.zeros_like(c.body.rest))


def test_depth_inside_a_closed_surface() -> None:
    """The depth below a point down to the surface, for points inside a unit cube; 0 outside."""
    corners = np.array([[x, y, z] for z in (0.0, 1.0) for y in (0.0, 1.0) for x in (0.0, 1.0)])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    faces = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    points = np.array([[0.3, 0.6, 0.25], [0.5, 0.5, 0.9], [0.5, 0.5, 1.5], [1.5, 0.5, 0.5]])
    np.testing.assert_allclose(depth_inside(points, corners, faces), [0.25, 0.9, 0.0, 0.0])


def test_roots_between_frames_are_c1_hermite(scene: jellysim.Scene) -> None:
    coupled = BellInFluid(scene)
    bell, margin = coupled.body, coupled.margin
    h = margin.frame_dt
    rng = np.random.default_rng(7)
    moved = bell.rest + 0.05 * rng.standard_normal(bell.rest.shape)
    velocity = rng.standard_normal(bell.rest.shape)
    margin.record(1, moved, velocity)
    # At the frame times the records themselves.
    p0, v0, _ = margin.roots(np.array([0.0]))
    p1, v1, _ = margin.roots(np.array([h]))
    record = margin.records[1]
    np.testing.assert_allclose(p1[0], record.roots, atol=1e-12)
    np.testing.assert_allclose(v1[0], record.velocities, atol=1e-12)
    np.testing.assert_allclose(v0[0], 0.0, atol=1e-12)
    # Velocity is the derivative of position (central differences inside the interval).
    t = np.array([0.4 * h - 1e-6, 0.4 * h, 0.4 * h + 1e-6])
    p, v, _ = margin.roots(t)
    np.testing.assert_allclose((p[2] - p[0]) / 2e-6, v[1], rtol=1e-5, atol=1e-6)


def test_skinned_surface_follows_rigid_motion(bell: SoftBell, skin: BellSkin) -> None:
    np.testing.assert_allclose(skin.surface(bell.rest), skin.rest_surface)
    shift = np.array([0.3, -0.2, 0.5])
    np.testing.assert_allclose(
        skin.surface(bell.rest + shift), skin.rest_surface + shift, atol=1e-12
    )
    outer = skin.rest_surface[1 : 1 + skin.sectors * 12]
    relative = outer - bell.shape.centre
    b = bell.shape
    on_ellipsoid = (np.hypot(relative[:, 0], relative[:, 1]) / b.radius) ** 2 + (
        relative[:, 2] / b.height
    ) ** 2
    np.testing.assert_allclose(on_ellipsoid, 1.0, atol=1e-12)


def test_spring_time_step_is_the_explicit_limit(bell: SoftBell) -> None:
    """dt <= SPRING_SAFETY x 2 / omega_max with omega_max from the stiffness matrix's largest
    eigenvalue at rest (the bound is conservative, not wildly), at several muscle activations."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import eigsh

    pairs = bell.springs.pairs
    e = bell.rest[pairs[:, 1]] - bell.rest[pairs[:, 0]]
    e /= np.linalg.norm(e, axis=1)[:, None]
    previous = math.inf
    for a in (0.0, 0.3, 1.0):
        k = bell.stiffness * np.where(
            bell.springs.muscle, 1.0 + (bell.muscle_stiffening - 1.0) * a, 1.0
        )
        block = k[:, None, None] * e[:, :, None] * e[:, None, :]  # (S, 3, 3)
        rows, cols, values = [], [], []
        for (i, j), b in zip(pairs, block, strict=True):
            for p, q, sign in ((i, i, 1.0), (j, j, 1.0), (i, j, -1.0), (j, i, -1.0)):
                r, c = np.meshgrid(3 * p + np.arange(3), 3 * q + np.arange(3), indexing="ij")
                rows.append(r.ravel())
                cols.append(c.ravel())
                values.append(sign * b.ravel())
        n = 3 * len(bell.rest)
        stiffness = coo_matrix(
            (np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
        ).tocsr()
        omega = math.sqrt(float(eigsh(stiffness, k=1, which="LA")[0][0]) / bell.mass)
        dt = bell.stable_dt(a)
        assert dt <= SPRING_SAFETY * 2.0 / omega * (1 + 1e-9)
        assert dt >= 0.35 * SPRING_SAFETY * 2.0 / omega  # twice the block bound: 0.39-0.5
        assert dt < previous  # a stiffer muscle, a shorter step
        previous = dt
    assert bell.stable_dt() == bell.stable_dt(1.0)


def _stretched(bell: SoftBell, factor: float = 1.01) -> np.ndarray:
    """The rest shape scaled about its centre (every spring stretched by ``factor``) with a
    small jitter that leaves them stretched."""
    rng = np.random.default_rng(5)
    centre = bell.rest.mean(axis=0)
    jitter = 1e-3 * L0 * rng.standard_normal(bell.rest.shape)
    return centre + factor * (bell.rest - centre) + jitter


def test_implicit_springs_solve_the_backward_euler_system(bell: SoftBell) -> None:
    """Linearised backward Euler [Baraff & Witkin 1998]: ``(m I - dt^2 K) dv = dt (F + dt K v)``
    with K = dF/dr; checked against a dense solve with K by central differences of the spring
    forces (all springs stretched, where K is the exact derivative)."""
    positions = _stretched(bell)
    rng = np.random.default_rng(6)
    velocities = 0.1 * rng.standard_normal(bell.rest.shape)
    time, dt = 0.3, 0.2  # the muscle half contracted, a step over 10x its explicit limit
    assert dt > 10 * bell.stable_dt()
    force = np.empty_like(positions)
    bell.implicit_force(positions, velocities, time, dt, force)

    n = positions.size
    explicit = np.empty_like(positions)
    bell.spring_forces(positions, time + dt, explicit)
    jacobian = np.empty((n, n))
    h = 1e-6 * L0
    plus, minus = np.empty_like(positions), np.empty_like(positions)
    for c in range(n):
        shifted = positions.copy().reshape(-1)
        shifted[c] += h
        bell.spring_forces(shifted.reshape(positions.shape), time + dt, plus)
        shifted[c] -= 2 * h
        bell.spring_forces(shifted.reshape(positions.shape), time + dt, minus)
        jacobian[:, c] = (plus - minus).reshape(-1) / (2 * h)
    system = bell.mass * np.eye(n) - dt**2 * jacobian
    rhs = dt * (explicit.reshape(-1) + dt * jacobian @ velocities.ravel())
    change = np.linalg.solve(system, rhs)
    expected = bell.mass * change.reshape(positions.shape) / dt
    scale = np.abs(expected).max()
    np.testing.assert_allclose(force, expected, atol=1e-6 * scale)
    # Internal forces: the implicit force has no net part either.
    np.testing.assert_allclose(force.sum(axis=0), 0.0, atol=1e-9 * scale)
    # A short step gives the explicit force back.
    bell.implicit_force(positions, velocities, time, 1e-7, force)
    bell.spring_forces(positions, time + 1e-7, explicit)
    np.testing.assert_allclose(force, explicit, atol=1e-4 * np.abs(explicit).max())


@pytest.mark.parametrize("implicit", [True, False])
def test_implicit_springs_stay_bounded_far_past_the_explicit_limit(
    bell: SoftBell, implicit: bool
) -> None:
    """The bell, released stretched by 5 % with the muscle fully contracted, stepped at 10x the
    explicit limit for 200 steps: implicit springs stay bounded and lose energy; the explicit
    force at that step blows up (which is why explicit runs keep dt under the limit)."""
    dt = 10 * bell.stable_dt()
    time = bell.period * bell.jet_fraction  # full contraction
    assert bell.activation(time) == pytest.approx(1.0)
    positions = _stretched(bell, 1.05)
    velocities = np.zeros_like(positions)
    force = np.empty_like(positions)
    largest = 0.0
    for _ in range(200):
        if implicit:
            bell.implicit_force(positions, velocities, time - dt, dt, force)
        else:
            bell.spring_forces(positions, time, force)
        velocities += dt * force / bell.mass
        positions += dt * velocities
        largest = max(largest, float(np.abs(positions - bell.rest).max()))
        if not np.isfinite(largest) or largest > 100 * bell.shape.radius:
            break
    if implicit:
        assert largest < bell.shape.radius
        assert np.abs(velocities).max() < 0.5  # m/s: damped, not ringing up
    else:
        assert largest > 100 * bell.shape.radius or not np.isfinite(largest)


def test_phase_lag_recovers_a_known_lag() -> None:
    """A speed that follows the contraction by 0.6 s, over a drift and a start-up pulse."""
    period, lag = 2.0, 0.6
    time = np.arange(0.0, 4 * period + 1e-9, 0.05)
    contraction = 0.2 + 0.1 * np.sin(2 * np.pi * time / period) + 0.01 * time
    speed = 0.3 + 0.05 * np.sin(2 * np.pi * (time - lag) / period)
    height = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * 0.05)])
    found = phase_lag(time, height, contraction, period)
    assert found is not None
    assert found.lag == pytest.approx(lag, abs=0.051)
    assert found.correlation > 0.9  # the linear detrend takes a little of each sine
    # Frames that do not divide the period, or no whole pulse after the first: no lag.
    assert phase_lag(time[:30], height[:30], contraction[:30], period) is None
    assert phase_lag(time, height, contraction, 2.03) is None
