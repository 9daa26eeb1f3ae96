"""Oral arms as ruffled ribbons (render/ribbons.py, docs/theory/ribbons.md): twist-free frames,
the ribbon's width, flatness, ruffle wavelength and amplitude, robustness, the POV-Ray mesh2
(parsed and rendered by the real povray) and the preview's triangles."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from jellysim.render import povray
from jellysim.render.frame import Camera, Look
from jellysim.render.preview import make_view, merge, rasterise
from jellysim.render.ribbons import (
    EDGE_POWER,
    RUFFLE_ROOT,
    catmull_rom,
    povray_ribbons,
    ribbon_frames,
    ribbon_mesh,
    ribbon_primitives,
)

OUTWARD = np.array([1.0, 0.0, 0.0])
ROWS = 9


def straight(length: float = 0.5, particles: int = 51) -> np.ndarray:
    """A chain hanging straight down from the origin, (particles, 3) m."""
    s = np.linspace(0.0, 1.0, particles)
    return np.stack([np.zeros_like(s), np.zeros_like(s), -length * s], axis=1)


def s_curve(length: float = 0.5, particles: int = 101) -> np.ndarray:
    """A chain hanging down in a gentle S in the x-z plane, (particles, 3) m."""
    s = np.linspace(0.0, 1.0, particles)
    return np.stack([0.04 * np.sin(2.0 * np.pi * s), np.zeros_like(s), -length * s], axis=1)


def grid(mesh_vertices: np.ndarray) -> np.ndarray:
    """A ribbon's vertices as (stations, ROWS, 3)."""
    return mesh_vertices.reshape(-1, ROWS, 3)


def test_frames_are_orthonormal_and_twist_free_along_a_planar_curve() -> None:
    points = s_curve()
    frames = ribbon_frames(points, np.array([0.0, 1.0, 0.0]))
    basis = np.stack([frames.tangent, frames.width, frames.binormal], axis=1)  # (P, 3, 3)
    gram = np.einsum("pik,pjk->pij", basis, basis)
    np.testing.assert_allclose(gram, np.broadcast_to(np.eye(3), gram.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(basis), 1.0, atol=1e-12)  # right-handed
    # The tangents point along the chain, root to tip.
    chord = np.gradient(points, axis=0)
    assert np.all(np.einsum("ij,ij->i", frames.tangent, chord) > 0.0)
    # A planar curve's rotation-minimising frame keeps the plane's normal (here y) as one
    # direction for its whole length: no twist about the tangent.
    np.testing.assert_allclose(frames.width, np.broadcast_to([0.0, 1.0, 0.0], (101, 3)), atol=1e-12)


def test_frames_transport_an_in_plane_width_without_twist() -> None:
    """Started in the curve's plane, the width stays in it (perpendicular to the tangent) and
    the binormal stays the plane's normal."""
    frames = ribbon_frames(s_curve(), OUTWARD)
    np.testing.assert_allclose(frames.width[:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.abs(frames.binormal[:, 1]), 1.0, atol=1e-12)
    assert np.all(frames.binormal[:, 1] * frames.binormal[0, 1] > 0.0)  # never flips


def test_frames_width_starts_along_the_outward_hint_made_perpendicular() -> None:
    frames = ribbon_frames(straight(), np.array([2.0, 0.0, 0.7]))  # tilted along the chain
    np.testing.assert_allclose(frames.width[0], OUTWARD, atol=1e-12)


def test_frames_survive_degenerate_input() -> None:
    # A hint along the tangent; points repeated at the root and inside; a chain that turns
    # straight back; a chain of one point.
    line = straight(particles=6)
    chains = [
        np.concatenate([line[:1], line[:3], line[2:3], line[3:]]),
        np.concatenate([line, line[-2::-1]]),
        np.zeros((3, 3)),
    ]
    for points in chains:
        frames = ribbon_frames(points, np.array([0.0, 0.0, -1.0]))
        for part in frames:
            assert np.all(np.isfinite(part))
            np.testing.assert_allclose(np.linalg.norm(part, axis=1), 1.0, atol=1e-12)
        along = np.einsum("ij,ij->i", frames.tangent, frames.width)
        np.testing.assert_allclose(along, 0.0, atol=1e-12)
    # The repeated root takes the first real direction, down the chain.
    np.testing.assert_allclose(ribbon_frames(chains[0], OUTWARD).tangent[0], [0.0, 0.0, -1.0])


def test_catmull_rom_passes_through_the_particles_and_keeps_a_straight_chain_even() -> None:
    points = s_curve(particles=11)
    curve = catmull_rom(points, 4)
    assert curve.shape == (41, 3)
    np.testing.assert_allclose(curve[::4], points, atol=1e-15)
    line = catmull_rom(straight(particles=6), 3)
    np.testing.assert_allclose(line, straight(particles=16), atol=1e-15)


def test_a_straight_ribbon_has_its_middle_on_the_centreline_and_the_given_widths() -> None:
    width, taper = 0.04, 0.3
    mesh = ribbon_mesh(
        straight(), OUTWARD, width, taper, ruffles=30.0, ruffle_depth=0.0, across=ROWS
    )
    vertices = grid(mesh.vertices)
    middle = vertices[:, ROWS // 2]
    np.testing.assert_allclose(middle[:, :2], 0.0, atol=1e-15)  # on the line x = y = 0
    np.testing.assert_allclose(middle[[0, -1], 2], [0.0, -0.5], atol=1e-15)
    span = np.linalg.norm(vertices[:, -1] - vertices[:, 0], axis=1)
    edge_to_edge = vertices[:, -1] - vertices[:, 0]
    np.testing.assert_allclose(edge_to_edge[:, 1:], 0.0, atol=1e-15)  # across is along x
    np.testing.assert_allclose(span[[0, -1]], [width, taper * width], rtol=1e-12)
    depth = -middle[:, 2]
    np.testing.assert_allclose(span, width * (1.0 - (1.0 - taper) * depth / 0.5), rtol=1e-12)


def test_without_ruffles_or_fold_the_ribbon_is_flat() -> None:
    mesh = ribbon_mesh(straight(), OUTWARD, 0.04, 0.3, 30.0, ruffle_depth=0.0, fold=0.0)
    # The plane of the centreline (z) and the width direction (x): y = 0.
    np.testing.assert_allclose(mesh.vertices[:, 1], 0.0, atol=1e-15)
    np.testing.assert_allclose(np.abs(mesh.normals[:, 1]), 1.0, atol=1e-12)


def test_the_fold_alone_bends_the_cross_section_into_a_parabola() -> None:
    width, fold = 0.04, 0.4
    mesh = ribbon_mesh(straight(), OUTWARD, width, 1.0, 30.0, ruffle_depth=0.0, fold=fold)
    root = grid(mesh.vertices)[0]  # the pleat's crest is at the root (phase 0)
    across = np.linspace(-1.0, 1.0, ROWS)
    np.testing.assert_allclose(np.abs(root[:, 1]), fold * width * across**2, atol=1e-15)


def edge_displacement(ruffles: float, depth: float, length: float = 1.0, phase: float = 0.0):
    """Out-of-plane displacement (m) of the +x edge of a straight, untapered ribbon without a
    fold, with the arc length (m) of its stations."""
    mesh = ribbon_mesh(
        straight(length, 201), OUTWARD, 0.04, 1.0, ruffles, depth, phase=phase, fold=0.0
    )
    vertices = grid(mesh.vertices)
    return vertices[:, -1, 1], -vertices[:, ROWS // 2, 2]


def test_the_edges_ruffle_with_the_requested_wavelength() -> None:
    for ruffles in (20.0, 45.0):
        displacement, arc = edge_displacement(ruffles, 0.4)
        crossings = np.count_nonzero(np.diff(np.sign(displacement)) != 0)
        # Two zero crossings a wave; the phase's meander (< 2 rad in all) may shift the count
        # by one at either end.
        assert abs(crossings - 2.0 * ruffles * arc[-1]) <= 2.0
        # At least STATIONS_PER_RUFFLE stations per wave, so each wave is drawn.
        assert len(arc) / (ruffles * arc[-1]) >= 8.0


def test_the_ruffles_have_the_requested_amplitude_growing_towards_the_tip() -> None:
    width, depth = 0.04, 0.4
    displacement, arc = edge_displacement(30.0, depth)
    envelope = width * depth * (RUFFLE_ROOT + (1.0 - RUFFLE_ROOT) * arc / arc[-1])
    ratio = np.abs(displacement) / envelope
    assert ratio.max() <= 1.0 + 1e-12
    for window in np.array_split(np.arange(len(arc)), 5):  # every fifth reaches its envelope
        assert ratio[window].max() > 0.9
    assert np.abs(displacement[-50:]).max() > 2.0 * np.abs(displacement[:50]).max()


def test_the_ruffles_grow_from_the_centre_line_to_the_edges() -> None:
    mesh = ribbon_mesh(straight(1.0, 201), OUTWARD, 0.04, 1.0, 30.0, 0.4, fold=0.0)
    out = np.abs(grid(mesh.vertices)[:, :, 1]).max(axis=0)  # (ROWS,) largest per row
    across = np.abs(np.linspace(-1.0, 1.0, ROWS))
    np.testing.assert_allclose(out, out[-1] * across**EDGE_POWER, rtol=0.1, atol=1e-15)


def test_the_phase_moves_the_ruffles() -> None:
    one, _ = edge_displacement(30.0, 0.4, phase=0.0)
    other, _ = edge_displacement(30.0, 0.4, phase=2.0)
    assert np.abs(one - other).max() > 0.5 * np.abs(one).max()


def test_trailing_nan_rows_are_dropped() -> None:
    chain = s_curve(particles=40)
    padded = np.concatenate([chain, np.full((15, 3), np.nan)])
    args = (OUTWARD, 0.04, 0.3, 40.0, 0.4)
    for trimmed, full in zip(ribbon_mesh(chain, *args), ribbon_mesh(padded, *args), strict=True):
        np.testing.assert_array_equal(trimmed, full)


@pytest.mark.parametrize(
    "chain",
    [np.full((5, 3), np.nan), np.zeros((1, 3)), np.zeros((4, 3)), np.empty((0, 3))],
    ids=["all-nan", "one-particle", "one-point-repeated", "empty"],
)
def test_fewer_than_two_distinct_finite_particles_give_an_empty_mesh(chain: np.ndarray) -> None:
    mesh = ribbon_mesh(chain, OUTWARD, 0.04, 0.3, 40.0, 0.4)
    assert mesh.vertices.shape == (0, 3) and mesh.normals.shape == (0, 3)
    assert mesh.faces.shape == (0, 3) and mesh.faces.dtype == np.int32


@pytest.mark.parametrize("taper", [0.0, 0.3])
def test_faces_are_valid_and_not_degenerate_and_normals_agree_with_the_winding(
    taper: float,
) -> None:
    mesh = ribbon_mesh(s_curve(), OUTWARD, 0.04, taper, 60.0, 0.5, phase=1.0)
    vertices, faces, normals = mesh
    assert faces.dtype == np.int32 and faces.min() >= 0 and faces.max() < len(vertices)
    assert np.all(np.isfinite(vertices)) and np.all(np.isfinite(normals))
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    face_normal = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(face_normal, axis=1)
    assert area.min() > 1e-6 * area.mean()
    # Two-sided but consistent: every vertex normal is on the front of its faces.
    agree = np.einsum("ij,ij->i", face_normal, normals[faces].sum(axis=1))
    assert np.all(agree > 0.0)


def test_povray_text_has_every_ribbon_in_one_mesh2_in_povray_coordinates() -> None:
    meshes = [
        ribbon_mesh(s_curve() + [0.1 * k, 0.0, 0.0], OUTWARD, 0.04, 0.3, 40.0, 0.4, k)
        for k in range(3)
    ]
    text = povray_ribbons(meshes, (0.5, 0.2, 0.6), Look())
    assert text.count("mesh2") == 1
    vertex_count = sum(len(mesh.vertices) for mesh in meshes)
    face_count = sum(len(mesh.faces) for mesh in meshes)
    assert f"vertex_vectors {{ {vertex_count}," in text
    assert f"normal_vectors {{ {vertex_count}," in text
    assert f"face_indices {{ {face_count}," in text
    first = meshes[0].vertices[0]
    assert povray.vec(first) in text  # y and z swapped, as everywhere else
    assert text.count("<") >= 2 * vertex_count + face_count
    assert "emission" not in text and "emission" in povray_ribbons(meshes, (1, 1, 1), Look(), True)
    assert (
        povray_ribbons(
            [ribbon_mesh(np.zeros((1, 3)), OUTWARD, 0.04, 0.3, 4, 0.4)], (1, 1, 1), Look()
        )
        == ""
    )


@pytest.mark.skipif(povray.find_povray() is None, reason="POV-Ray is not installed")
def test_povray_renders_a_ruffled_ribbon(tmp_path: Path) -> None:
    mesh = ribbon_mesh(s_curve(), OUTWARD, 0.04, 0.35, 60.0, 0.4, phase=0.3)
    camera = Camera(np.array([0.3, -0.5, -0.2]), np.array([0.0, 0.0, -0.25]), angle=45.0)
    size = (48, 64)
    look = Look()
    scene = (
        "#version 3.7;\nglobal_settings { assumed_gamma 1.0 max_trace_level 5 }\n"
        + povray.camera_block(camera, size)
        + povray.lights_block(camera, 0.5, povray.QUALITIES["draft"])
        + "background { rgb <0,0,0.1> }\n"
    )
    pictures = []
    for body in ("", povray_ribbons([mesh], (0.6, 0.3, 0.7), look, glow=True)):
        path = tmp_path / f"ribbon{len(pictures)}.pov"
        path.write_text(scene + body, encoding="utf-8")
        image = path.with_suffix(".png")
        povray.render_file("povray", path, image, size, povray.QUALITIES["draft"], 1)
        pictures.append(matplotlib.image.imread(image)[..., :3])
    ribbon = np.abs(pictures[1] - pictures[0]).max(axis=2) > 0.02
    assert 0.02 * ribbon.size < ribbon.sum() < 0.5 * ribbon.size  # drawn, and a ribbon's size
    rows = np.nonzero(ribbon.any(axis=1))[0]
    assert rows.max() - rows.min() > 0.6 * size[1]  # it hangs down most of the picture


def test_preview_triangles_draw_the_ribbon() -> None:
    mesh = ribbon_mesh(s_curve(), OUTWARD, 0.04, 0.35, 60.0, 0.4)
    camera = Camera(np.array([0.3, -0.5, -0.2]), np.array([0.0, 0.0, -0.25]), angle=45.0)
    view = make_view(camera, 60, 80)
    drawn = ribbon_primitives([mesh], (0.6, 0.3, 0.7), Look(), view, near=0.01)
    assert drawn.corners.shape == (len(mesh.faces), 4, 2)  # all in view
    assert np.all((drawn.rgba >= 0.0) & (drawn.rgba <= 1.0))
    assert np.all(drawn.rgba[:, 3] > 0.0)  # translucent, not invisible
    distance = np.linalg.norm(mesh.vertices[mesh.faces].mean(axis=1) - camera.location, axis=1)
    np.testing.assert_allclose(drawn.distance, distance)
    background = np.zeros((view.height, 3))
    image = rasterise(merge([drawn]), background, view)
    covered = image.max(axis=2) > 0.05
    assert 0.01 * covered.size < covered.sum() < 0.5 * covered.size
    rows = np.nonzero(covered.any(axis=1))[0]
    assert rows.max() - rows.min() > 0.6 * view.height  # it hangs down most of the picture
    empty = ribbon_primitives([], (1.0, 1.0, 1.0), Look(), view, 0.01)
    assert len(empty.distance) == 0
    assert math.isclose(float(np.linalg.norm(view.forward)), 1.0)
