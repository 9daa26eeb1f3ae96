"""The tentacle-bell contact (docs/theory/tentacle.md §8, Eq. T15-T16): a particle inside the
bell's drawn shell is put on the nearest point of its surface, after each substep."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from shells import inside_closed_surface

from jellysim.bell.kinematic import bell_faces
from jellysim.tentacle.contact import (
    CLEARANCE,
    Obstacle,
    _closest_on_triangle,
    inside_shell,
    no_obstacle,
    push_out,
    shell_obstacle,
)
from jellysim.tentacle.kernels import (
    CONTACT_GAP,
    WALL_RELEASE_ABOVE,
    ChainModel,
    Medium,
    _keep_out,
    advance_frame,
    project_lengths,
    project_on_walls,
)
from jellysim.tentacle.model import build_chain_model

# A closed box [0, 1] x [0, 1] x [0, 0.5], its 12 triangles facing outwards.
BOX_VERTICES = np.array(
    [[x, y, z] for z in (0.0, 0.5) for y in (0.0, 1.0) for x in (0.0, 1.0)], dtype=np.float64
)
BOX_FACES = np.array(
    [
        [0, 2, 1], [1, 2, 3],  # bottom
        [4, 5, 6], [5, 7, 6],  # top
        [0, 1, 4], [1, 5, 4],  # y = 0
        [2, 6, 3], [3, 6, 7],  # y = 1
        [0, 4, 2], [2, 4, 6],  # x = 0
        [1, 3, 5], [3, 7, 5],  # x = 1
    ]
)  # fmt: skip


def shell(sectors: int = 48) -> tuple[np.ndarray, np.ndarray]:
    """A bell shell of the soft bell's skin topology: outer half-ellipsoid of radius 1 and height
    0.5, the inner one 0.1 inside."""
    from jellysim.bell.kinematic import MESH_RINGS

    s = np.arange(1, MESH_RINGS + 1) / MESH_RINGS
    ring_s = np.concatenate([s, s[-2::-1]])
    outer = np.arange(len(ring_s)) < MESH_RINGS
    a = 0.5 * np.pi * ring_s
    r = np.where(outer, 1.0, 0.9)
    h = np.where(outer, 0.5, 0.4)
    angles = 2 * np.pi * np.arange(sectors) / sectors
    rho = (r * np.sin(a))[:, None] * np.ones(sectors)
    z = (h * np.cos(a))[:, None] * np.ones(sectors)
    rings = np.stack([rho * np.cos(angles), rho * np.sin(angles), z], axis=-1).reshape(-1, 3)
    vertices = np.concatenate([[[0.0, 0.0, 0.5]], rings, [[0.0, 0.0, 0.4]]])
    return vertices, bell_faces(sectors)


def push(x: np.ndarray, old: np.ndarray, obstacle: Obstacle, tau: float) -> int:
    """:func:`push_out` on chain ``x`` from ``old``, its root (particle 0) prescribed."""
    return push_out(x, old, 1, obstacle, tau, np.zeros(len(x), bool), np.empty((11, 3)))


def test_the_nearest_point_of_a_triangle_matches_a_dense_search() -> None:
    # Ericson's Voronoi-region walk against the minimum over 20,301 barycentric samples: for
    # points off every vertex, edge and the face, the distances agree to the sampling's error.
    rng = np.random.default_rng(3)
    n = 200
    u, v = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1))
    keep = u + v <= 1.0
    u, v = u[keep], v[keep]
    work, out = np.empty((5, 3)), np.empty(3)
    for _ in range(50):
        corners = rng.normal(size=(3, 3))
        p = rng.normal(size=3) * 2.0
        samples = (
            corners[0]
            + u[:, None] * (corners[1] - corners[0])
            + v[:, None] * (corners[2] - corners[0])
        )
        dense = np.sqrt(np.min(np.sum((samples - p) ** 2, axis=1)))
        exact = np.sqrt(_closest_on_triangle(p, corners, work, out))
        edge = max(np.linalg.norm(corners[1] - corners[0]), np.linalg.norm(corners[2] - corners[0]))
        assert exact <= dense + 1e-12
        assert dense - exact <= edge / n  # the samples' spacing bounds the dense search's error
        np.testing.assert_allclose(np.linalg.norm(out - p), exact, rtol=1e-12)


def test_the_parity_rule_agrees_with_the_check_on_stored_results() -> None:
    # The kernel's inside test and the one tests/integration uses on results classify 4,000
    # points in and around a bell shell alike.
    vertices, faces = shell()
    obstacle = shell_obstacle(vertices, vertices, faces)
    rng = np.random.default_rng(7)
    points = rng.uniform([-1.1, -1.1, -0.1], [1.1, 1.1, 0.6], size=(4000, 3))
    corners = np.empty((3, 3))
    ours = np.array([inside_shell(p, obstacle, 0.5, corners) for p in points])
    np.testing.assert_array_equal(ours, inside_closed_surface(points, vertices, faces))
    assert 100 < ours.sum() < 3900  # both kinds of point were tried


def test_a_particle_in_the_wall_goes_to_the_nearest_surface() -> None:
    # Inside the box, 0.1 below its top and 0.3 and more from every other face: put on the top,
    # CLEARANCE of the box's size (1) above it; particles outside are left exactly where they are.
    obstacle = shell_obstacle(BOX_VERTICES, BOX_VERTICES, BOX_FACES)
    x = np.array([[0.5, 0.5, 2.0], [0.4, 0.3, 0.4], [1.5, 0.5, 0.25], [0.7, 0.6, -0.2]])
    before = x.copy()
    moved = push(x, x.copy(), obstacle, 0.0)
    assert moved == 1
    assert obstacle.clearance == CLEARANCE
    np.testing.assert_allclose(x[1], [0.4, 0.3, 0.5 + obstacle.clearance], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(np.delete(x, 1, axis=0), np.delete(before, 1, axis=0))


def test_a_particle_that_moved_in_stops_where_its_path_meets_the_surface() -> None:
    # From 0.2 above the box's top to 0.05 above its bottom in one step: the nearest face is the
    # bottom, the far side of the box, but the particle came in through the top and stays there
    # (the contact never moves a particle through the shell). The root, inside the box too, is
    # prescribed and stays where it is.
    obstacle = shell_obstacle(BOX_VERTICES, BOX_VERTICES, BOX_FACES)
    old = np.array([[0.5, 0.5, 0.25], [0.3, 0.6, 0.7]])
    x = np.array([[0.5, 0.5, 0.25], [0.3, 0.6, 0.05]])
    assert push(x, old, obstacle, 0.0) == 1
    np.testing.assert_allclose(x[1], [0.3, 0.6, 0.5 + obstacle.clearance], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(x[0], [0.5, 0.5, 0.25])


def test_the_shell_moves_linearly_through_the_frame() -> None:
    # The box rises by 1 over the frame: at tau = 0.5 it spans z in [0.5, 1.0], and a particle
    # at z = 0.6 is put on its bottom, the nearer face.
    obstacle = shell_obstacle(BOX_VERTICES, BOX_VERTICES + [0.0, 0.0, 1.0], BOX_FACES)
    x = np.array([[0.5, 0.5, 2.0], [0.45, 0.55, 0.6]])
    assert push(x.copy(), x.copy(), obstacle, 0.0) == 0  # at the start the box is below
    assert push(x, x.copy(), obstacle, 0.5) == 1
    np.testing.assert_allclose(x[1], [0.45, 0.55, 0.5 - obstacle.clearance], atol=1e-15)


def test_no_obstacle_is_the_paper_model() -> None:
    x = np.array([[0.5, 0.5, 2.0], [0.4, 0.3, 0.4]])
    assert push(x, x.copy(), no_obstacle(), 0.0) == 0


def hanging_chain(particles: int = 21, spacing: float = 0.02) -> tuple[ChainModel, Medium]:
    model = build_chain_model(particles, spacing, 1.0e5, 1100.0)
    medium = Medium(1000.0, 1.0e-3, np.array([0.0, 0.0, -9.81]), 1100.0)
    return model, medium


@pytest.mark.parametrize("contact", [False, True])
def test_a_sweeping_wall_pushes_a_hanging_chain_and_never_passes_it(contact: bool) -> None:
    """A slab 0.2 m thick sweeps sideways at 0.5 m/s through the lower half of a 0.4 m chain
    hanging from a fixed root. With the contact no particle is ever inside it, and the chain's
    lower part is carried on the wall's front face (inelastic: it does not bounce off ahead);
    without it the wall passes through the chain (the paper's model)."""
    model, medium = hanging_chain()
    particles, spacing = 21, 0.02
    down = np.array([0.0, 0.0, -1.0])
    x = (np.arange(particles)[:, None] * spacing * down)[None].copy()
    v = np.zeros_like(x)
    # The slab: x in [-0.5, -0.3] at the start, moving to +x; z in [-1, -0.2], y in [-1, 1].
    slab = BOX_VERTICES * [0.2, 2.0, 1.6] + [-0.5, -1.0, -1.0]
    speed, fps, substeps = 0.5, 50, 10
    dt = 1.0 / (fps * substeps)
    zeros = np.zeros((substeps, 1, 3))
    inside_any = 0
    for frame in range(50):  # 1 s: the slab's front travels from -0.3 to 0.2
        start = slab + [speed * frame / fps, 0.0, 0.0]
        end = slab + [speed * (frame + 1) / fps, 0.0, 0.0]
        obstacle = shell_obstacle(start, end, BOX_FACES) if contact else no_obstacle()
        diagnostics = np.zeros((1, 3))
        advance_frame(
            x, v, zeros, zeros, zeros + down, zeros, np.zeros_like(x), zeros[:, :, None],
            model, medium, dt, diagnostics, np.zeros((1, 0, 3)), obstacle,
        )  # fmt: skip
        assert diagnostics[0, 2] == -1
        # The segments keep their length exactly (Eq. T17), in the diagnostics and in the state.
        lengths = np.linalg.norm(np.diff(x[0], axis=0), axis=1)
        assert diagnostics[0, 0] <= 1e-10
        np.testing.assert_allclose(lengths, spacing, rtol=1e-9)
        inside_any += int(inside_closed_surface(x[0, 1:], end, BOX_FACES).sum())
    if contact:
        assert inside_any == 0
        # The particles below the slab's top (z = -0.2) lie on its front face, x = 0.2 at the
        # end, pushed ahead of it (to within a spacing: they slide on it as the chain swings up);
        # those above it drape over its top.
        below = x[0, :, 2] < -0.2
        assert below.sum() >= 5
        assert np.all((x[0, below, 0] >= 0.2) & (x[0, below, 0] < 0.2 + spacing))
    else:
        assert inside_any > 100
        assert abs(x[0, -1, 0]) < 0.01  # the wall went through: the chain still hangs


def wall_work(particles: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Scratch of :func:`project_on_walls` for a chain of ``particles``."""
    rows = 2 * particles - 1
    return np.empty((particles - 1, 3)), np.empty((rows, 3)), np.empty(rows), np.empty(particles)


def test_the_projection_on_walls_without_a_wall_is_the_length_projection() -> None:
    """No particle pinned: :func:`project_on_walls` solves the same Newton steps as
    :func:`project_lengths` (Eq. T8), by a band solve instead of the Thomas algorithm."""
    rng = np.random.default_rng(3)
    particles, spacing = 15, 0.02
    steps = rng.normal(size=(particles - 1, 3))
    steps *= spacing / np.linalg.norm(steps, axis=1, keepdims=True)
    x = np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])
    x[1:] += rng.normal(scale=0.1 * spacing, size=(particles - 1, 3))  # lengths off by ~10 %
    inverse_mass = np.ones(particles)
    inverse_mass[0] = 0.0
    a, b = x.copy(), x.copy()
    done_a = project_lengths(
        a,
        inverse_mass,
        spacing,
        1e-12,
        50,
        np.empty((particles - 1, 3)),
        np.empty((4, particles - 1)),
    )
    pinned = np.zeros(particles, bool)
    done_b = project_on_walls(
        b, inverse_mass, spacing, 1e-12, 50, pinned, np.zeros_like(x), np.zeros_like(x),
        *wall_work(particles),
    )  # fmt: skip
    assert done_a == done_b > 2
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-14)


def test_a_particle_on_a_wall_slides_along_its_tangent_plane() -> None:
    """A chain bent over a wall z = 0 with particles 3..9 put on it (pushed up from inside, their
    segments stretched): projected together with their planes (Eq. T17), they stay on the wall
    and slide along it, the lengths exact; the other particles take up the rest."""
    particles, spacing = 10, 0.02
    angle = np.radians(20.0)
    x = np.arange(particles)[:, None] * spacing * np.array([np.cos(angle), 0.0, -np.sin(angle)])
    x[:, 2] += 2.5 * spacing * np.sin(angle)  # particles 3.. start below z = 0
    below = x[:, 2] < 0.0
    assert below[3:].all() and not below[:3].any()
    x[below, 2] = 0.0  # pushed straight up onto the wall
    pinned = below.copy()
    normals = np.zeros_like(x)
    normals[:, 2] = 1.0
    surface = x.copy()
    inverse_mass = np.ones(particles)
    inverse_mass[0] = 0.0
    edges, band, rhs, pushes = wall_work(particles)
    done = project_on_walls(
        x, inverse_mass, spacing, 1e-12, 50, pinned, surface, normals, edges, band, rhs, pushes
    )
    assert done > 0
    np.testing.assert_allclose(np.linalg.norm(np.diff(x, axis=0), axis=1), spacing, rtol=1e-11)
    np.testing.assert_allclose(x[below, 2], 0.0, atol=1e-13)
    assert np.all(np.abs(x[below, 0] - surface[below, 0]) > 5e-5)  # they slid, not stood
    # the wall held them out, not in: what it moved them into it is round-off
    assert np.all(inverse_mass[below] * pushes[below] <= WALL_RELEASE_ABOVE * spacing)
    assert inverse_mass[3] * pushes[3] < -1e-3 * spacing  # the first one is pressed on it


def advance_recorded_frame(name: str, contact: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One recorded frame of one `moon-jelly` fringe tentacle (``tests/data/<name>.npz``, see
    tests/data/README.md) through :func:`advance_frame`, with the bell's shell or without it: its
    positions (P, 3) after the frame, the kernel's diagnostics (3,) and the shell's vertices at
    the frame's end."""
    data = np.load(Path(__file__).parents[1] / "data" / f"{name}.npz")

    def fields(prefix: str, names: tuple[str, ...]) -> dict[str, object]:
        values = {name: data[f"{prefix}_{name}"] for name in names}
        return {name: v.item() if v.ndim == 0 else v for name, v in values.items()}

    model = ChainModel(**fields("model", ChainModel._fields))
    medium = Medium(**fields("medium", Medium._fields))
    obstacle = shell_obstacle(data["shell_start"], data["shell_end"], bell_faces(50))
    x = data["positions"][None].copy()
    v = data["velocities"][None].copy()
    diagnostics = np.zeros((1, 3))
    advance_frame(
        x, v, data["root_positions"][:, None], data["root_velocities"][:, None],
        data["root_directions"][:, None], data["curl_normals"][:, None], np.zeros_like(x),
        data["flow"][:, None], model, medium, float(data["dt"]), diagnostics,
        np.zeros((1, 0, 3)), obstacle if contact else no_obstacle(),
    )  # fmt: skip
    return x[0], diagnostics[0], data["shell_end"]


def test_a_fringe_tentacle_pressed_under_the_margin_slides_along_it() -> None:
    """One of `moon-jelly`'s fringe tentacles over the frame in which its margin re-opens over it
    (t = 1.65-1.70 s; tests/data/README.md). Particles 3 and 4 are pushed into the wall above
    the root in every substep. Held where they were pushed (the rounds before the planes of
    Eq. T17), the projection pulled them back in: 2 particles inside after the frame, 2.2 mm
    deep. Kept on the wall's tangent planes, the chain slides along the wall: none inside, the
    lengths exact."""
    x, diagnostics, shell_end = advance_recorded_frame("moon_jelly_fringe_under_the_margin", True)
    faces = bell_faces(50)
    assert diagnostics[2] == -1
    assert diagnostics[0] <= 1e-10
    assert not inside_closed_surface(x[1:], shell_end, faces).any()
    # and it is the wall that moved them: without the contact, particle 3 ends inside
    y, _, _ = advance_recorded_frame("moon_jelly_fringe_under_the_margin", False)
    assert inside_closed_surface(y, shell_end, faces)[3]


# A root beside the box's face x = 1, 10 mm out and 40 mm above its bottom, and its neighbour,
# one spacing (30 mm) away at 45 degrees down and in, 11 mm inside x = 1 and 19 mm above the
# bottom, through which it came in.
ROOT_BESIDE_THE_BOX = np.array([1.01, 0.5, 0.04])
ROUND_THE_CORNER = 0.03 * np.array([-1.0, 0.0, -1.0]) / np.sqrt(2.0)


def test_a_push_beyond_the_roots_reach_stops_on_the_roots_segment() -> None:
    """Eq. T16b. The particle's path came in through the box's bottom, but the bottom's plane
    lies 40 mm from the root, beyond its 30 mm segment: no point of it can hold the particle
    (the projection on it fails). It is put where its segment from the root meets the box, on
    the face x = 1, whose plane is 10 mm from the root; a chain with a free first particle (no
    prescribed root) keeps the push along its path."""
    spacing = 0.03
    root = ROOT_BESIDE_THE_BOX
    x = np.array([root, root + ROUND_THE_CORNER])
    old = x.copy()
    old[1] = [0.97, 0.5, -0.005]  # below the bottom at the step's start
    obstacle = shell_obstacle(BOX_VERTICES, BOX_VERTICES, BOX_FACES)
    gap = CONTACT_GAP * spacing
    out = obstacle.clearance + gap

    def pushed(reach: float, first: int = 1) -> tuple[np.ndarray, np.ndarray]:
        y, normals = x.copy(), np.zeros((2, 3))
        moved = push_out(
            y, old, first, obstacle, 1.0, np.zeros(2, bool), np.empty((11, 3)), gap, normals, reach
        )
        assert moved == 1
        return y[1], normals[1]

    along_the_path, bottom = pushed(0.0)
    np.testing.assert_allclose(bottom, [0.0, 0.0, -1.0], atol=1e-12)
    path = (x[1] - old[1]) / np.linalg.norm(x[1] - old[1])
    assert along_the_path[2] == pytest.approx(-out * path[2], rel=1e-9)  # stopped on its path
    assert bottom @ (root - along_the_path) < -spacing  # the root 40 mm on the plane's far side
    on_the_side, side = pushed(spacing)
    np.testing.assert_allclose(side, [1.0, 0.0, 0.0], atol=1e-12)
    # stopped short of the face along the segment, at 45 degrees to the face's normal
    assert on_the_side[0] == pytest.approx(1.0 + out / np.sqrt(2.0), rel=1e-12)
    direction = (x[1] - root) / np.linalg.norm(x[1] - root)
    np.testing.assert_allclose(np.cross(on_the_side - root, direction), 0.0, atol=1e-15)
    assert 0.0 < side @ (root - on_the_side) < spacing  # within the segment's reach
    # The bottom's plane cannot hold it at its length; the side's can.
    for y, normal in ((along_the_path, bottom), (on_the_side, side)):
        chain = np.array([root, y])
        edges, band, rhs, pushes = wall_work(2)
        done = project_on_walls(
            chain, np.array([0.0, 1.0]), spacing, 1e-10, 50, np.array([False, True]),
            np.array([y, y]), np.array([normal, normal]), edges, band, rhs, pushes,
        )  # fmt: skip
        assert (done >= 0) == (normal is side)
    # A chain without a prescribed root can move its particle 0 to the plane: no reach rule.
    np.testing.assert_array_equal(pushed(spacing, first=0)[0], along_the_path)


def test_a_chain_whose_root_is_beside_the_wall_is_pushed_round_it() -> None:
    """The contact's rounds (Eq. T15-T17) on a chain of three particles hanging from the root
    beside the box (above): particle 1 came in through the bottom, particle 2 hangs below it.
    Put on the bottom (the push along its path), its plane out of the root's reach, the
    projection fell back to holding it, and the lengths pulled it back into the box, towards the
    root, in every round. Put where its segment from the root meets the side, it
    slides down the side: no particle inside, the lengths exact, particle 1 on the side's
    plane."""
    spacing = 0.03
    root = ROOT_BESIDE_THE_BOX
    x = np.array([root, root + ROUND_THE_CORNER, root + ROUND_THE_CORNER + [0.0, 0.0, -spacing]])
    old = x.copy()
    old[1:] = [[0.97, 0.5, -0.005], [0.97, 0.5, -0.035]]  # below the bottom at the start
    assert inside_closed_surface(x[1:], BOX_VERTICES, BOX_FACES).tolist() == [True, False]
    obstacle = shell_obstacle(BOX_VERTICES, BOX_VERTICES, BOX_FACES)
    particles = 3
    rows = 2 * particles - 1
    iterations = _keep_out(
        x, old, 1, obstacle, 1.0, np.array([0.0, 1.0, 1.0]), spacing, 0, np.empty((2, 3)),
        np.empty((4, 2)), np.zeros(particles, bool), np.empty(particles),
        np.zeros(particles, bool), np.empty((11, 3)), np.zeros((4, particles, 3)),
        np.empty((rows, 3)), np.empty(rows),
    )  # fmt: skip
    assert iterations >= 0
    np.testing.assert_allclose(np.linalg.norm(np.diff(x, axis=0), axis=1), spacing, rtol=1e-10)
    assert not inside_closed_surface(x[1:], BOX_VERTICES, BOX_FACES).any()
    assert x[1, 0] > 1.0  # on the side, outside
    assert x[1, 0] - 1.0 < obstacle.clearance + CONTACT_GAP * spacing


def test_a_fringe_tentacle_swept_round_the_rim_stays_out_of_it() -> None:
    """One of `moon-jelly`'s fringe tentacles over the frame t = 9.40-9.45 s, as the bell, pressed
    flat at the water's surface, turns its margin up past the root (tests/data/README.md): the
    root passes from 29 mm below the drawn underside to 17 mm beside the rim's outer face, and
    its first particle, which came in through the underside, is inside from the sixth of the
    frame's 7 substeps. Put on the underside, whose plane then lies 36-45 mm from the root,
    beyond its 30 mm segment, the projection could not hold it and the lengths pulled it back
    in: particles 1 and 2 ended the frame inside, 3.5 and 1.9 mm deep (docs/figures.md, note
    11). Put where its segment from the root meets the rim (Eq. T16b) none is inside, the lengths
    exact and no projection failed; particle 1 lies 4.9 mm off the rim."""
    x, diagnostics, shell_end = advance_recorded_frame("moon_jelly_fringe_round_the_rim", True)
    faces = bell_faces(50)
    assert diagnostics[2] == -1
    assert diagnostics[0] <= 1e-10
    assert not inside_closed_surface(x[1:], shell_end, faces).any()
    spacing = 0.03
    np.testing.assert_allclose(np.linalg.norm(np.diff(x, axis=0), axis=1), spacing, rtol=1e-9)
    # Without the contact none would end the frame inside either (particle 1 3.4 mm out): it was
    # the held projection that pulled particles 1 and 2 in.
    y, _, _ = advance_recorded_frame("moon_jelly_fringe_round_the_rim", False)
    assert not inside_closed_surface(y[1:], shell_end, faces).any()


def test_a_projection_step_on_walls_is_the_dense_newton_step() -> None:
    """One Newton step of :func:`project_on_walls` (Eq. T17) against a dense solve of the same
    step, ``(J W J^T) lambda = C``, ``x -= W J^T lambda``, on random chains with random planes
    (pinned particles, normals and points) and masses: the band's entries, its LDL^T and the
    update agree to round-off, and ``pushes`` holds the planes' multipliers."""
    rng = np.random.default_rng(11)
    for trial in range(40):
        particles = int(rng.integers(2, 9))
        spacing = 0.05
        x = np.cumsum(rng.normal(scale=spacing, size=(particles, 3)), axis=0)
        inverse_mass = rng.uniform(0.5, 2.0, particles)
        if trial % 2:
            inverse_mass[0] = 0.0  # a prescribed root
        pinned = (rng.random(particles) < 0.5) & (inverse_mass > 0)
        normals = rng.normal(size=(particles, 3))
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        surface = x + rng.normal(scale=0.2 * spacing, size=(particles, 3))
        # The dense step: rows of J for the segments, then the pinned particles' planes.
        rows, residual = [], []
        for j in range(particles - 1):
            e = x[j + 1] - x[j]
            row = np.zeros((particles, 3))
            row[j + 1], row[j] = 2 * e, -2 * e
            rows.append(row.ravel())
            residual.append(e @ e - spacing**2)
        planes = np.flatnonzero(pinned)
        for i in planes:
            row = np.zeros((particles, 3))
            row[i] = normals[i]
            rows.append(row.ravel())
            residual.append(normals[i] @ (x[i] - surface[i]))
        jacobian = np.array(rows)
        weights = np.repeat(inverse_mass, 3)
        multipliers = np.linalg.solve((jacobian * weights) @ jacobian.T, np.array(residual))
        expected = x - (weights * (jacobian.T @ multipliers)).reshape(particles, 3)
        actual = x.copy()
        edges, band, rhs, pushes = wall_work(particles)
        project_on_walls(
            actual, inverse_mass, spacing, 1e-300, 1, pinned, surface, normals, edges, band, rhs,
            pushes,
        )  # fmt: skip
        np.testing.assert_allclose(actual, expected, rtol=0, atol=1e-12 * spacing)
        np.testing.assert_allclose(
            pushes[planes], multipliers[particles - 1 :], rtol=1e-9, atol=1e-12
        )


def test_a_wall_that_would_hold_a_particle_in_lets_it_go() -> None:
    """Particle 1 of a chain of one segment (d = 0.08 m) hangs from a root 0.05 m above the box's
    top face and 0.1 m aside; the wall came over it (0.05 m inside). Put on the top face it is
    0.112 m from the root, too far: kept on the face, the length would pull it along the face and
    the face would hold it down, into the wall (its multiplier positive). The contact only pushes
    (Eq. T17), so that plane is let go: the particle rises off the wall, straight towards the
    root, to its length, and ends outside the box."""
    spacing = 0.08
    root = np.array([0.6, 0.5, 0.55])
    x = np.array([root, [0.5, 0.5, 0.45]])
    old = x.copy()
    obstacle = shell_obstacle(BOX_VERTICES, BOX_VERTICES, BOX_FACES)
    inverse_mass = np.array([0.0, 1.0])
    particles = 2
    rows = 2 * particles - 1
    iterations = _keep_out(
        x, old, 1, obstacle, 1.0, inverse_mass, spacing, 0, np.empty((1, 3)), np.empty((4, 1)),
        np.zeros(particles, bool), np.empty(particles), np.zeros(particles, bool),
        np.empty((11, 3)), np.zeros((4, particles, 3)), np.empty((rows, 3)), np.empty(rows),
    )  # fmt: skip
    assert iterations >= 0
    assert np.linalg.norm(x[1] - root) == pytest.approx(spacing, rel=1e-10)
    pushed = np.array([0.5, 0.5, 0.5 + obstacle.clearance + CONTACT_GAP * spacing])  # the push
    toward_root = (root - pushed) / np.linalg.norm(root - pushed)
    np.testing.assert_allclose(
        (x[1] - pushed) / np.linalg.norm(x[1] - pushed), toward_root, atol=1e-9
    )
    assert x[1, 2] > 0.5 + 0.01  # off the wall, not slid along it at z = 0.5
    assert not inside_closed_surface(x[1:], BOX_VERTICES, BOX_FACES).any()


def test_a_fringe_tentacle_under_the_upturned_margin_stays_out_of_it() -> None:
    """Another of `moon-jelly`'s fringe tentacles, over the frame t = 9.60-9.65 s (tests/data/
    README.md): the margin, turned up, lies over the chain, and particle 3, which came in through
    the underside, is inside in the frame's last three substeps. Put on the underside, whose plane
    lay 88-94 mm from the root, beyond the 90 mm of chain between them, the projection could not
    hold it and the lengths pulled it back in: 4.0 mm deep after the frame. Put where the line
    from the root meets the wall (Eq. T16b, particle i within i spacings of the root) none is
    inside and the lengths are exact; without the contact particle 3 ends inside."""
    name = "moon_jelly_fringe_under_the_upturned_margin"
    x, diagnostics, shell_end = advance_recorded_frame(name, True)
    faces = bell_faces(50)
    assert diagnostics[2] == -1
    assert diagnostics[0] <= 1e-10
    assert not inside_closed_surface(x[1:], shell_end, faces).any()
    np.testing.assert_allclose(np.linalg.norm(np.diff(x, axis=0), axis=1), 0.03, rtol=1e-9)
    y, _, _ = advance_recorded_frame(name, False)
    assert inside_closed_surface(y, shell_end, faces)[3]
