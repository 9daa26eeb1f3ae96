"""The built-in preview renderer: pinhole projection, exact PNG size, where the jellyfish lands,
perspective, depth order through the translucent bell, fog, robustness and determinism."""

import math

import numpy as np
import pytest
from matplotlib.image import imread

from jellysim.errors import InputError
from jellysim.render.frame import Camera, Frame, Jellyfish, Look, vertex_normals
from jellysim.render.preview import make_view, project, render_preview

SIZE = (160, 120)
LOOK = Look()
RADIUS, HEIGHT = 0.1, 0.08  # m: the test bell, margin at z = 0, apex at z = HEIGHT


def dome(radius=RADIUS, height=HEIGHT, rings=10, sectors=24, offset=(0.0, 0.0, 0.0)):
    """An open UV hemi-ellipsoid, apex up, margin at z = 0: vertices (V, 3), faces (M, 3)
    counter-clockwise seen from outside."""
    polar = np.linspace(0.0, 0.5 * np.pi, rings + 1)[1:]
    azimuth = 2.0 * np.pi * np.arange(sectors) / sectors
    rho = radius * np.sin(polar)[:, None]
    z = np.broadcast_to(height * np.cos(polar)[:, None], (rings, sectors))
    rings_xyz = np.stack([rho * np.cos(azimuth), rho * np.sin(azimuth), z], axis=-1)
    vertices = np.concatenate([[[0.0, 0.0, height]], rings_xyz.reshape(-1, 3)]) + offset
    j = np.arange(sectors)
    jn = (j + 1) % sectors
    faces = [np.stack([np.zeros(sectors, int), 1 + j, 1 + jn], axis=1)]
    for ring in range(rings - 1):
        a, b = 1 + ring * sectors, 1 + (ring + 1) * sectors
        faces += [np.stack([a + j, b + j, b + jn], axis=1), np.stack([a + j, b + jn, a + jn], 1)]
    return vertices, np.concatenate(faces)


def hanging_tentacles(count=6, particles=20, length=0.2, radius=0.9 * RADIUS):
    """Straight tentacles (count, particles, 3) hanging from a ring at z = 0."""
    angle = 2.0 * np.pi * np.arange(count) / count
    s = np.linspace(0.0, 1.0, particles)
    return np.stack(
        [
            np.broadcast_to(radius * np.cos(angle)[:, None], (count, particles)),
            np.broadcast_to(radius * np.sin(angle)[:, None], (count, particles)),
            np.broadcast_to(-length * s, (count, particles)),
        ],
        axis=-1,
    )


def jellyfish(bell=True, tentacles=None, look=LOOK):
    vertices, faces = dome() if bell else (None, None)
    tentacles = hanging_tentacles() if tentacles is None else tentacles
    return Jellyfish(tentacles, vertices, faces, look)


def camera_at(distance, angle=40.0):
    """On the +x axis at height -0.05 m, looking along -x at the jellyfish's middle."""
    return Camera(np.array([distance, 0.0, -0.05]), np.array([0.0, 0.0, -0.05]), angle=angle)


def render(tmp_path, frame, camera, name="frame.png", **options):
    path = render_preview(frame, camera, SIZE, tmp_path / name, **options)
    return (imread(path)[:, :, :3] * 255.0).round().astype(int)


def background(tmp_path, camera):
    """The picture of the same water with nothing in it."""
    empty = Jellyfish(np.empty((0, 2, 3)), None, None, LOOK)
    return render(tmp_path, Frame(0.0, [empty]), camera, "background.png")


def foreground(image, empty):
    return np.abs(image - empty).max(axis=2) > 2


def test_test_dome_faces_outward():
    vertices, faces = dome()
    normals = vertex_normals(vertices, faces)
    outward = np.einsum("ij,ij->i", normals, vertices)  # the dome is centred on the origin
    assert (outward > 0.0).all()


def test_projection_is_a_pinhole_with_horizontal_field_of_view():
    camera = camera_at(1.0, angle=60.0)
    view = make_view(camera, 200, 100)
    # On the axis: the image centre. At half the field of view to the right (+y here, since the
    # camera looks along -x with z up), the right edge. Up is up, at the same focal length.
    half = math.tan(math.radians(30.0))
    points = np.array([[0.0, 0.0, -0.05], [0.0, half, -0.05], [-1.0, 2 * half, -0.05 + half]])
    pixels, depth = project(points, view)
    np.testing.assert_allclose(depth, [1.0, 1.0, 2.0])
    np.testing.assert_allclose(pixels, [[100.0, 50.0], [200.0, 50.0], [200.0, 0.0]], atol=1e-9)


def test_png_has_the_size_and_shows_the_jellyfish_around_its_projected_centre(tmp_path):
    camera = camera_at(1.0)
    image = render(tmp_path, Frame(0.0, [jellyfish()]), camera)
    assert image.shape == (SIZE[1], SIZE[0], 3)
    empty = background(tmp_path, camera)
    # The background is a vertical gradient, darker at the bottom, from the water colour at the
    # top: (0.05, 0.2, 0.35) linear is (63.1, 123.5, 159.7) / 255 in sRGB (IEC 61966-2-1).
    assert (empty[0] == empty[0, 0]).all() and empty[-1].sum() < empty[0].sum()
    assert np.abs(empty[0, 0] - [63.1, 123.5, 159.7]).max() < 1.5

    mask = foreground(image, empty)
    rows, cols = np.nonzero(mask)
    assert mask.sum() > 300
    assert rows.min() > 0 and cols.min() > 0
    assert rows.max() < SIZE[1] - 1 and cols.max() < SIZE[0] - 1
    # Bell centre (mean of its vertices) by hand: camera at x = 1 m looking along -x, so the
    # depth is 1 - x, right is +y, up is +z; f = 80 / tan 20 deg.
    vertices, _ = dome()
    centre = vertices.mean(axis=0)
    focal = 80.0 / math.tan(math.radians(20.0))
    depth = 1.0 - centre[0]
    x = 80.0 + focal * centre[1] / depth
    y = 60.0 - focal * (centre[2] + 0.05) / depth
    assert cols.min() < x < cols.max() and rows.min() < y < rows.max()
    assert mask[int(y), int(x)]
    # The widest part is the margin (radius R at z = 0): the point at angle t from the camera's
    # side projects at f R sin t / (1 - R cos t), largest at cos t = R: f R / sqrt(1 - R^2).
    # Antialiasing adds at most a pixel at each side.
    width = 2.0 * focal * RADIUS / math.sqrt(1.0 - RADIUS**2)
    assert abs((cols.max() + 1 - cols.min()) - width) <= 2.0


def test_a_farther_camera_makes_a_smaller_jellyfish(tmp_path):
    areas = []
    for distance in (1.0, 2.0):
        camera = camera_at(distance)
        image = render(tmp_path, Frame(0.0, [jellyfish()]), camera)
        areas.append(foreground(image, background(tmp_path, camera)).sum())
    # Perspective: area ~ 1 / depth^2, a quarter at twice the distance (thin tentacles keep
    # their minimum width, so somewhat more).
    assert 0 < areas[1] < 0.4 * areas[0]


def test_points_behind_the_camera_are_left_out(tmp_path):
    camera = camera_at(0.5)
    visible = hanging_tentacles()
    behind = visible + [1.0, 0.0, 0.0]  # x = 1.1 m, behind the camera at x = 0.5 m
    crossing = np.linspace([0.2, 0.02, -0.05], [0.8, 0.02, -0.05], 20)[None]  # through it
    alone = render(tmp_path, Frame(0.0, [jellyfish(tentacles=visible)]), camera, "a.png")
    more = Frame(
        0.0,
        [jellyfish(tentacles=np.concatenate([visible, behind]))],
        fluid=np.array([[1.0, 0.0, 0.0], [0.6, 0.0, -0.05]]),
        fluid_radius=0.01,
    )
    assert (render(tmp_path, more, camera, "b.png") == alone).all()
    crossed = Frame(0.0, [jellyfish(tentacles=np.concatenate([visible, crossing]))])
    image = render(tmp_path, crossed, camera, "c.png")
    assert image.shape == (SIZE[1], SIZE[0], 3) and (image != alone).any()


def test_the_same_input_gives_the_same_png(tmp_path):
    frame = Frame(0.0, [jellyfish()], fluid=np.zeros((5, 3)), fluid_radius=0.005)
    first = render_preview(frame, camera_at(1.0), SIZE, tmp_path / "1.png")
    second = render_preview(frame, camera_at(1.0), SIZE, tmp_path / "2.png")
    assert first.read_bytes() == second.read_bytes()


def test_tentacles_without_a_bell_and_fluid_particles_are_drawn(tmp_path):
    camera = camera_at(1.0)
    empty = background(tmp_path, camera)
    tentacles_only = render(tmp_path, Frame(0.0, [jellyfish(bell=False)]), camera)
    assert foreground(tentacles_only, empty).sum() > 50

    fluid = np.array([[0.0, -0.2, 0.1], [0.0, 0.2, -0.2], [0.3, 0.1, 0.0]])
    frame = Frame(0.0, [jellyfish(bell=False)], fluid=fluid, fluid_radius=0.004)
    mask = foreground(render(tmp_path, frame, camera), tentacles_only)
    pixels, _ = project(fluid, make_view(camera, *SIZE))
    for x, y in pixels:
        assert mask[int(y), int(x)]
    assert mask.sum() < 60  # small dots: about pi (0.004 f / depth)^2 px each


def test_tentacles_interleave_with_the_translucent_bell_by_depth(tmp_path):
    """A thick vertical tentacle in front of the bell keeps its own colour where it crosses the
    bell; one behind the bell shows through it, mixed with the bell's colour."""
    camera = camera_at(1.0)
    look = Look(tentacle_color=(0.1, 0.8, 0.1), tentacle_radius=0.02, tentacle_taper=1.0)
    vertical = np.linspace([0.0, 0.0, 0.12], [0.0, 0.0, -0.15], 12)[None]
    bell_only = render(tmp_path, Frame(0.0, [jellyfish(tentacles=vertical[:0])]), camera)
    # A green tentacle about 9 px wide.
    col, in_bell, below_bell = 80, 40, 75  # rows at z = 0.04 (bell: 0 to 0.08) and z = -0.1
    for x in (0.15, -0.15):  # in front of the bell, behind it
        frame = Frame(0.0, [jellyfish(tentacles=vertical + [x, 0.0, 0.0], look=look)])
        image = render(tmp_path, frame, camera, f"{x}.png")
        change = np.abs(image[in_bell, col] - image[below_bell, col]).max()
        if x > 0.0:
            assert change <= 3  # opaque, in front: the bell does not show
        else:
            assert change > 30  # behind: the bell's colour is mixed in
            assert np.abs(image[in_bell, col] - bell_only[in_bell, col]).max() > 5  # seen


def test_fog_fades_a_receding_bell_into_the_water(tmp_path):
    camera = camera_at(1.0)
    empty = background(tmp_path, camera)
    contrasts = []
    for shift in (0.0, -1.0):  # the same bell, 1 m farther from the fixed camera
        vertices, faces = dome(offset=(shift, 0.0, -0.09))  # the eye level in the middle
        frame = Frame(0.0, [Jellyfish(np.empty((0, 2, 3)), vertices, faces, LOOK)])
        image = render(tmp_path, frame, camera, f"{shift}.png")
        contrasts.append(np.abs(image[60, 80] - empty[60, 80]).sum())
    assert 0 < contrasts[1] < 0.5 * contrasts[0]


def test_final_quality_keeps_the_size_and_unknown_quality_is_refused(tmp_path):
    image = render(tmp_path, Frame(0.0, [jellyfish()]), camera_at(1.0), quality="final")
    assert image.shape == (SIZE[1], SIZE[0], 3)
    with pytest.raises(InputError, match="quality"):
        render_preview(Frame(0.0, []), camera_at(1.0), SIZE, tmp_path / "x.png", "best")


def test_ribbon_arms_show_in_their_colour_below_the_bell_and_threads_in_theirs(tmp_path):
    from types import SimpleNamespace

    from jellysim.render.frame import DrawnTentacles
    from jellysim.render.materials import group_look

    angle = 0.5 * np.pi * np.arange(4) + 0.25 * np.pi  # no arm edge-on to the camera on +x
    roots = 0.02 * np.stack([np.cos(angle), np.sin(angle), np.zeros(4)], axis=1)
    arms = roots[:, None] + np.linspace(0.0, 1.0, 10)[:, None] * np.array([0.0, 0.0, -0.15])
    green = SimpleNamespace(color=(0.05, 0.8, 0.1), form="ribbon", ribbon_width=0.04, spacing=0.01)
    red = SimpleNamespace(color=(0.9, 0.05, 0.05), drawn_radius=0.004, spacing=0.01)
    vertices, faces = dome()
    groups = (
        DrawnTentacles(hanging_tentacles(), group_look(LOOK, red, "marginal")),
        DrawnTentacles(arms, group_look(LOOK, green, "oral_arms"), 6),
    )
    jelly = Jellyfish(np.empty((0, 2, 3)), vertices, faces, LOOK, groups, np.zeros(3))
    camera = camera_at(0.6)
    image = render(tmp_path, Frame(0.0, [jelly]), camera).astype(float)
    view = make_view(camera, *SIZE)
    (_, margin_row), _ = project(np.array([0.0, 0.0, 0.0]), view)
    below = image[int(margin_row) + 3 :]
    r, g, b = below[..., 0], below[..., 1], below[..., 2]
    arm_pixels = (g > r + 40) & (g > b + 20)
    thread_pixels = (r > g + 40) & (r > b + 20)
    assert arm_pixels.sum() > 100  # the curtains, in their own green, under the bell
    assert thread_pixels.sum() > 30  # the threads in their red
    columns = np.nonzero(arm_pixels.any(axis=0))[0]
    assert abs(0.5 * (columns.min() + columns.max()) - SIZE[0] / 2) < 10  # centred under it
