"""The POV-Ray scene text (no POV-Ray needed): the poster look's elements at final quality and
not at draft, the look keys that switch them off, the Fresnel-like rim as numbers, and the same
input giving the same text, with water particles that stay put from frame to frame."""

from __future__ import annotations

import math
import re
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from jellysim.config import load_scene
from jellysim.render import povray
from jellysim.render.frame import Camera, Frame, Jellyfish, Look
from jellysim.render.materials import bell_transmit
from jellysim.render.pipeline import scene_look

SIZE = (160, 120)
CAMERA = Camera(np.array([0.0, -1.0, 0.1]), np.array([0.0, 0.0, -0.1]))
SNOW = re.compile(r"sphere\{<([^>]*)>,[^ ]+ pigment\{rgb")


def octahedron(radius: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """A closed mesh: vertices (6, 3) m, faces (8, 3) counter-clockwise seen from outside."""
    vertices = radius * np.array(
        [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float
    )
    faces = np.array(
        [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    )
    return vertices, faces


STRIPED = Look(stripes=8)


def frame(look: Look = STRIPED, time: float = 0.0, closed: bool = True) -> Frame:
    vertices, faces = octahedron()
    if not closed:
        faces = faces[:-1]
    tentacles = np.stack([np.linspace([0.05, 0.0, 0.0], [0.05, 0.0, -0.3], 10)] * 3)
    return Frame(time, [Jellyfish(tentacles, vertices, faces, look)])


def text(
    quality: str,
    look: Look = STRIPED,
    *,
    time: float = 0.0,
    camera: Camera = CAMERA,
    closed: bool = True,
    seed: int = 0,
    room: tuple[np.ndarray, np.ndarray] | None = None,
) -> str:
    scene = frame(look, time, closed)
    return povray.scene_text(
        scene, camera, SIZE, povray.QUALITIES[quality], 0.4, room=room, seed=seed
    )


def snow(scene: str) -> np.ndarray:
    """The marine snow's centres (K, 3), in POV-Ray's coordinates."""
    return np.array([[float(c) for c in m.split(",")] for m in SNOW.findall(scene)])


def test_final_adds_depth_of_field_light_shafts_and_the_bells_media_draft_does_not() -> None:
    draft, final = text("draft"), text("final")
    for element in ("aperture", "focal_point", "cylinder {", "media {", "inside_vector"):
        assert element in final and element not in draft, element
    assert "scattering {" in final and "ior 1.02" in final
    # Both: the Fresnel-like rim (aoi), the stripes, the tapered tentacles, the snow, the fog.
    for scene in (draft, final):
        assert "aoi pigment_map" in scene and "radial frequency 8" in scene
        assert "cone{" in scene and "fog {" in scene
        assert len(snow(scene)) == Look().marine_snow


def test_look_keys_switch_the_effects_off() -> None:
    look = Look(stripes=0, marine_snow=0, light_shafts=0.0, depth_of_field=0.0)
    final = text("final", look)
    assert not snow(final).size and "cylinder {" not in final and "radial" not in final
    # No depth of field: a pinhole's aperture, the blur samples left to antialias.
    aperture = float(re.search(r"aperture ([^\s]+)", final).group(1))  # type: ignore[union-attr]
    assert aperture < 1e-3 * np.linalg.norm(CAMERA.look_at - CAMERA.location)


def test_an_open_bell_gets_no_media() -> None:
    final = text("final", closed=False)
    assert "media {" not in final and "inside_vector" not in final and "ior 1.02" in final


def test_no_snow_or_shafts_among_fluid_particles_or_in_the_room() -> None:
    fluid = replace(frame(), fluid=np.zeros((5, 3)), fluid_radius=0.01)
    scene = povray.scene_text(fluid, CAMERA, SIZE, povray.QUALITIES["final"], 0.4)
    assert not snow(scene).size and "cylinder {" not in scene
    room = povray.room_box(np.array([-0.1, -0.1, -0.3]), np.array([0.1, 0.1, 0.1]))
    assert not snow(text("final", room=room)).size


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_the_same_input_gives_the_same_text_and_the_seed_moves_the_water(quality: str) -> None:
    assert text(quality, seed=3) == text(quality, seed=3)
    assert text(quality, seed=3) != text(quality, seed=4)


def test_the_snow_drifts_a_little_between_frames_and_stays_put_as_the_camera_moves() -> None:
    distance = float(np.linalg.norm(CAMERA.look_at - CAMERA.location))
    now, later = snow(text("draft")), snow(text("draft", time=1.0 / 30.0))
    step = np.linalg.norm(later - now, axis=1)
    assert np.median(step) > 0.0  # drifting
    assert np.mean(step < 0.005 * distance) > 0.99  # slowly: the rest wrapped round the tiling
    # A camera following a swimmer upwards: the particles keep their world places.
    up = np.array([0.0, 0.0, 0.05])
    moved = replace(CAMERA, location=CAMERA.location + up, look_at=CAMERA.look_at + up)
    followed = snow(text("draft", camera=moved))
    kept = np.linalg.norm(followed - now, axis=1) < 1e-6
    assert 0.9 < kept.mean() < 1.0  # most stay; those the moved tiling left re-enter opposite


def test_the_rim_is_clear_face_on_and_opaque_and_light_at_the_silhouette() -> None:
    look = Look(bell_transparency=0.5, rim=0.6)
    face, face_light = bell_transmit(look, 1.0)
    edge, edge_light = bell_transmit(look, 0.0)
    assert (face, face_light) == pytest.approx((0.5 + 0.5 * 0.6, 0.0))
    assert (edge, edge_light) == pytest.approx((0.5 * 0.4, 0.6))
    angles = np.linspace(0.0, 0.5 * math.pi, 20)
    transmits = [float(bell_transmit(look, math.cos(a))[0]) for a in angles]
    assert np.all(np.diff(transmits) < 0)  # falls monotonically towards the silhouette
    # rim = 0: the same transparency at every angle, as before the rim existed.
    flat = replace(look, rim=0.0)
    assert {tuple(map(float, bell_transmit(flat, math.cos(a)))) for a in angles} == {(0.5, 0.0)}


def test_closed_meshes_are_told_from_open_ones() -> None:
    vertices, faces = octahedron()
    assert povray.is_closed(faces) and not povray.is_closed(faces[:-1])


def test_stripes_default_to_half_the_lobes_and_new_look_keys_reach_the_renderer() -> None:
    brown = load_scene("brown-jelly")
    assert scene_look(brown).stripes == brown.bell.lobes // 2 > 0
    look = scene_look(brown, ["look.stripes=0", "look.rim=0.2", "look.marine_snow=7"])
    assert (look.stripes, look.rim, look.marine_snow) == (0, 0.2, 7)


# sha256 of text("draft") and text("final") as the branch's starting commit (b86ea3a, before
# tentacle groups reached the renderers) wrote them: a one-group jellyfish's scene is unchanged
# but for the ``// object NAME`` comment lines that name each object since (issue 27).
STARTING_COMMIT_SHA256 = {
    "draft": "d1544cb297ac2865d306bd4f4f8fe4131711b487a173e0e901bd445c40fcb029",
    "final": "b9ad75f8a88fbae496844cf2faa8b0284d5c7ffc97e6693c2bc2247dc0ff2672",
}


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_a_one_group_scene_is_the_text_of_the_starting_commit(quality: str) -> None:
    import hashlib

    scene = text(quality)
    assert "// object bell\n" in scene
    unnamed = re.sub(r"^// object .*\n", "", scene, flags=re.M)
    assert hashlib.sha256(unnamed.encode()).hexdigest() == STARTING_COMMIT_SHA256[quality]


def two_groups(padding: int = 0) -> Frame:
    """The octahedron bell with red threads (margin) and four green ribbon arms hung from a
    manubrium; the arms' positions padded with ``padding`` NaN rows, trimmed as the pipeline
    trims them."""
    from jellysim.render.frame import DrawnTentacles, Manubrium
    from jellysim.render.materials import group_look
    from jellysim.render.pipeline import finite_rows

    vertices, faces = octahedron()
    look = Look()
    threads = np.stack([np.linspace([0.1, 0.0, 0.0], [0.1, 0.0, -0.3], 12)] * 3)
    angle = 0.5 * np.pi * np.arange(4)
    roots = 0.02 * np.stack([np.cos(angle), np.sin(angle), np.zeros(4)], axis=1)
    arms = roots[:, None] + np.linspace(0.0, 1.0, 8)[:, None] * np.array([0.0, 0.0, -0.2])
    arms = np.concatenate([arms, np.full((4, padding, 3), np.nan)], axis=1)
    tentacles = SimpleNamespace(
        color=(0.9, 0.1, 0.1), form="thread", drawn_radius=0.003, spacing=0.01
    )
    oral = SimpleNamespace(
        color=(0.1, 0.8, 0.2), form="ribbon", placement="mouth", ribbon_width=0.03, spacing=0.01
    )
    groups = (
        DrawnTentacles(threads, group_look(look, tentacles, "marginal")),
        DrawnTentacles(finite_rows(arms), group_look(look, oral, "oral_arms"), 3),
    )
    stalk = Manubrium(np.array([0.0, 0.0, 0.05]), np.zeros(3), 0.03, 0.02)
    jelly = Jellyfish(
        np.empty((0, 2, 3)), vertices, faces, look, groups, np.zeros(3), manubrium=stalk
    )
    return Frame(0.0, [jelly])


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_each_group_is_drawn_in_its_look_and_no_nan_reaches_the_scene(quality: str) -> None:
    scene = povray.scene_text(two_groups(padding=5), CAMERA, SIZE, povray.QUALITIES[quality], 0.4)
    assert "nan" not in scene.lower()
    assert scene.count("mesh2 {") == 2  # the bell and the ribbon arms
    ribbon = scene[scene.rindex("mesh2 {") :]
    assert "<0.1,0.8,0.2," in ribbon  # the arms' colour, with its transmit
    assert "rgb <0.9,0.1,0.1>" in scene  # the threads' colour at their edges
    assert "cone{<0.1,0,0>,0.003," in scene  # the threads' own root radius
    assert "cone { <0,0.05,0>, 0.03, <0,0,0>, 0.02" in scene  # the manubrium
    # The arms are drawn to their last finite particle, as without padding.
    unpadded = povray.scene_text(two_groups(), CAMERA, SIZE, povray.QUALITIES[quality], 0.4)
    assert scene == unpadded


def test_arms_do_not_ruffle_in_lockstep() -> None:
    from jellysim.render.povray import arm_meshes
    from jellysim.render.ribbons import ROWS

    jelly = two_groups().jellyfish[0]
    meshes = arm_meshes(jelly, jelly.groups[1])
    # Turned into one arm's place, the four arms' surfaces differ: each has its own phase.
    shapes = []
    for k, mesh in enumerate(meshes):
        turn = -0.5 * np.pi * k
        rotation = np.array(
            [[np.cos(turn), -np.sin(turn), 0.0], [np.sin(turn), np.cos(turn), 0.0], [0, 0, 1]]
        )
        shapes.append(mesh.vertices @ rotation.T)
    assert all(len(s) == len(shapes[0]) for s in shapes)
    assert min(np.abs(s - shapes[0]).max() for s in shapes[1:]) > 1e-3
    # Each arm's width starts radially out from the axis at its root.
    for k, mesh in enumerate(meshes):
        across = mesh.vertices[ROWS - 1] - mesh.vertices[0]  # the root's row, edge to edge
        radial = np.array([np.cos(0.5 * np.pi * k), np.sin(0.5 * np.pi * k), 0.0])
        assert abs(across @ radial) > 0.8 * np.linalg.norm(across)
