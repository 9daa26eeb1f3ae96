"""``jellysim export --format gltf``: binary glTF parts read back with pygltflib and compared with
result.h5 (the y-up conversion undone), checked by the Khronos glTF-Validator (zero errors,
warnings, infos and hints) and played by three.js's GLTFLoader and AnimationMixer under Node.js.

Node.js and ``web/node_modules`` (``make web``) are needed for the validator and three.js tests:
skipped without them, except where the environment variable CI is set (CI installs both).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

import jellysim
from jellysim import fields
from jellysim.export import export
from jellysim.export import gltf as gltf_export
from jellysim.interpolation import interpolate_result
from jellysim.render.frame import tentacle_radii
from jellysim.render.materials import GLOW_EMISSION
from jellysim.render.pipeline import scene_look

pygltflib = pytest.importorskip("pygltflib", reason="pygltflib is a test dependency (.[test])")

HERE = Path(__file__).parent
NODE_MODULES = HERE.parents[1] / "web" / "node_modules"
SIDES = gltf_export.TUBE_SIDES
COMPONENTS = {5126: np.float32, 5123: np.uint16, 5125: np.uint32}
WIDTHS = {"SCALAR": 1, "VEC3": 3}


@pytest.fixture(scope="module")
def brown(tmp_path_factory: pytest.TempPathFactory) -> jellysim.Result:
    folder = tmp_path_factory.mktemp("brown")
    # brown-jelly's marginal tentacles alone (the oral arms are a second group: the exports of
    # groups are tests/integration/test_export_groups.py's), 60 particles a tentacle: the counts
    # below assume them (the preset has 90 since issue 25).
    overrides = {"duration": 0.4, "fps": 10.0, "tentacles.particles": 60}
    scene = jellysim.load_scene("brown-jelly", overrides).group_scene(0)
    return jellysim.run(scene, folder)


@pytest.fixture(scope="module")
def exported(brown: jellysim.Result, tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    return export(brown, "gltf", tmp_path_factory.mktemp("gltf"), interpolation=2)


def node_and_modules() -> str:
    """The node executable; skips (fails under CI) without Node.js or web/node_modules."""
    node = shutil.which("node")
    missing = []
    if node is None:
        missing.append("Node.js (apt-get install nodejs)")
    for package in ("gltf-validator", "three"):
        if not (NODE_MODULES / package / "package.json").is_file():
            missing.append(f"web/node_modules/{package} (make web)")
    if missing:
        message = "missing " + ", ".join(missing)
        if os.environ.get("CI"):
            pytest.fail(message + "; CI must install them")
        pytest.skip(message)
    assert node is not None
    return node


def validate(paths: list[Path]) -> list[dict]:
    node = node_and_modules()
    done = subprocess.run(
        [node, str(HERE / "gltf_validate.mjs"), str(NODE_MODULES), *map(str, paths)],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    return json.loads(done.stdout)


def assert_valid(paths: list[Path], allowed_infos: tuple[str, ...] = ()) -> None:
    """No error, warning, info or hint, except infos named in ``allowed_infos``."""
    reports = validate(paths)
    assert len(reports) == len(paths)
    for report in reports:
        issues = report["issues"]
        others = [m for m in issues["messages"] if m["code"] not in allowed_infos]
        assert others == [], report["uri"]
        assert all(m["severity"] == 2 for m in issues["messages"])  # 2: info
        counts = [issues[k] for k in ("numErrors", "numWarnings", "numHints")]
        assert counts == [0, 0, 0]
        assert issues["numInfos"] == len(issues["messages"])
        assert report["info"]["generator"].startswith("jellysim ")


class Glb:
    """A .glb read with pygltflib, with its accessors as numpy arrays."""

    def __init__(self, path: Path) -> None:
        self.doc = pygltflib.GLTF2().load(str(path))
        self.blob = self.doc.binary_blob()

    def array(self, index: int) -> np.ndarray:
        accessor = self.doc.accessors[index]
        view = self.doc.bufferViews[accessor.bufferView]
        dtype = np.dtype(COMPONENTS[accessor.componentType])
        width = WIDTHS[accessor.type]
        start = view.byteOffset + accessor.byteOffset
        assert view.byteStride in (None, dtype.itemsize * width)  # tightly packed
        assert start + accessor.count * width * dtype.itemsize <= view.byteOffset + view.byteLength
        data = np.frombuffer(self.blob, dtype, accessor.count * width, start)
        return data.reshape(accessor.count, width) if width > 1 else data

    def frame_nodes(self) -> dict[int, pygltflib.Node]:
        root = self.doc.nodes[self.doc.scenes[self.doc.scene].nodes[0]]
        nodes = [self.doc.nodes[i] for i in root.children]
        return {int(n.name.removeprefix("frame_")): n for n in nodes}

    def primitive(self, node: pygltflib.Node, material: str) -> pygltflib.Primitive | None:
        for primitive in self.doc.meshes[node.mesh].primitives:
            if self.doc.materials[primitive.material].name == material:
                return primitive
        return None

    def keyframes(self, node_index: int) -> tuple[np.ndarray, np.ndarray]:
        (channel,) = [c for c in self.doc.animations[0].channels if c.target.node == node_index]
        assert channel.target.path == "scale"
        sampler = self.doc.animations[0].samplers[channel.sampler]
        assert sampler.interpolation == "STEP"
        return self.array(sampler.input), self.array(sampler.output)


def z_up(points: np.ndarray) -> np.ndarray:
    """glTF's y-up points back in jellysim's z-up: (x, y, z) -> (x, -z, y)."""
    return np.stack([points[:, 0], -points[:, 2], points[:, 1]], axis=1)


def signed_volume(points: np.ndarray, triangles: np.ndarray) -> float:
    """Volume enclosed by a closed triangle mesh: positive for counter-clockwise faces seen
    from outside (divergence theorem)."""
    a, b, c = (points[triangles[:, k]].astype(np.float64) for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def test_bell_and_tentacles_match_the_result(brown: jellysim.Result, exported: list[Path]) -> None:
    part, index = exported
    assert part.name == "brown-jelly_part000.glb" and index.name == "brown-jelly.gltf-parts.json"
    glb = Glb(part)
    assert glb.doc.asset.version == "2.0"
    assert glb.doc.asset.generator == gltf_export.generator()
    frames = glb.frame_nodes()
    assert sorted(frames) == list(range(brown.frames))
    assert len(glb.doc.meshes) == brown.frames and len(glb.doc.nodes) == brown.frames + 1
    drawn = interpolate_result(brown, 2)
    count, particles = 12, 60  # 6 simulated tentacles x 2, 60 particles each
    assert drawn.shape[1:3] == (count, particles)
    radii = tentacle_radii(particles, scene_look(brown.scene))
    faces = brown.file[fields.BELL_SURFACE_FACES.path][:]
    for frame in (0, 2, brown.frames - 1):
        node = frames[frame]
        bell = glb.primitive(node, "bell")
        vertices = glb.array(bell.attributes.POSITION)
        np.testing.assert_allclose(
            z_up(vertices), brown.file[fields.BELL_SURFACE_VERTICES.path][frame], atol=1e-6
        )
        accessor = glb.doc.accessors[bell.attributes.POSITION]
        assert accessor.min == vertices.min(axis=0).tolist()
        assert accessor.max == vertices.max(axis=0).tolist()
        triangles = glb.array(bell.indices).reshape(-1, 3)
        np.testing.assert_array_equal(triangles, faces)
        assert signed_volume(vertices, triangles) > 0.0  # winding kept through the rotation

        tubes = glb.primitive(node, "tentacles")
        points = glb.array(tubes.attributes.POSITION)
        normals = glb.array(tubes.attributes.NORMAL)
        assert points.shape == (count * (particles * SIDES + 2), 3)
        np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6)
        per_tube = z_up(points).reshape(count, particles * SIDES + 2, 3)
        rings = per_tube[:, : particles * SIDES].reshape(count, particles, SIDES, 3)
        np.testing.assert_allclose(rings.mean(axis=2), drawn[frame], atol=1e-6)  # centred
        distance = np.linalg.norm(rings - drawn[frame][:, :, None], axis=-1)
        np.testing.assert_allclose(distance, np.broadcast_to(radii[:, None], distance.shape), 1e-4)
        np.testing.assert_allclose(per_tube[:, -2], drawn[frame][:, 0], atol=1e-6)  # root cap
        np.testing.assert_allclose(per_tube[:, -1], drawn[frame][:, -1], atol=1e-6)  # tip cap
        tube_triangles = glb.array(tubes.indices).reshape(-1, 3)
        one = particles * SIDES + 2
        for k in (0, count - 1):
            mine = tube_triangles[(tube_triangles >= k * one).all(axis=1)]
            mine = mine[(mine < (k + 1) * one).all(axis=1)]
            assert signed_volume(points, mine) > 0.0  # closed, outward
        outward = np.einsum(
            "ij,ij->i",
            z_up(normals).reshape(count, -1, 3)[:, : particles * SIDES].reshape(-1, 3),
            (rings - drawn[frame][:, :, None]).reshape(-1, 3),
        )
        assert np.all(outward > 0.0)


def test_materials_come_from_the_scene_look(brown: jellysim.Result, exported: list[Path]) -> None:
    glb = Glb(exported[0])
    look = scene_look(brown.scene)
    materials = {m.name: m for m in glb.doc.materials}
    assert sorted(materials) == ["bell", "tentacles"]
    bell = materials["bell"]
    assert bell.alphaMode == "BLEND"
    np.testing.assert_allclose(
        bell.pbrMetallicRoughness.baseColorFactor, [*look.bell_color, 1 - look.bell_transparency]
    )
    np.testing.assert_allclose(
        bell.emissiveFactor, np.multiply(GLOW_EMISSION * look.glow, look.bell_color)
    )
    assert bell.doubleSided
    tentacles = materials["tentacles"]
    np.testing.assert_allclose(
        tentacles.pbrMetallicRoughness.baseColorFactor, [*look.tentacle_color, 1.0]
    )
    assert tentacles.alphaMode in (None, "OPAQUE")


def test_animation_switches_one_frame_on_at_a_time(
    brown: jellysim.Result, exported: list[Path]
) -> None:
    glb = Glb(exported[0])
    fps = 10.0
    last = brown.frames - 1
    root = glb.doc.nodes[0]
    samples = (np.arange(brown.frames) + 0.5) / fps  # mid-frame times
    shown = np.zeros((len(samples), brown.frames), dtype=bool)
    for node_index in root.children:
        node = glb.doc.nodes[node_index]
        frame = int(node.name.removeprefix("frame_"))
        times, scales = glb.keyframes(node_index)
        assert np.all(np.diff(times) > 0)  # strictly increasing
        frame_times = np.float32(np.arange(brown.frames + 1) / fps)
        assert np.isin(times, frame_times).all()  # keyframes at frame / fps only
        assert np.float32(frame / fps) in times  # shown at frame / fps
        assert np.all((scales == 0.0) | (scales == 1.0))
        expected_static = [1.0, 1.0, 1.0] if frame == 0 else [0.0, 0.0, 0.0]
        assert (node.scale or [1.0, 1.0, 1.0]) == expected_static
        step = np.searchsorted(times, samples, side="right") - 1
        shown[:, frame] = scales[np.maximum(step, 0), 0] == 1.0
    np.testing.assert_array_equal(shown, np.eye(brown.frames, dtype=bool))
    last_times, _ = glb.keyframes(root.children[-1])
    assert last_times[-1] == pytest.approx((last + 1) / fps)  # the last frame held one interval
    assert glb.doc.asset.extras["fps"] == fps


def test_exported_files_pass_the_khronos_validator(exported: list[Path]) -> None:
    assert_valid(exported[:1])


def test_three_js_plays_the_frames_in_turn(brown: jellysim.Result, exported: list[Path]) -> None:
    node = node_and_modules()
    times = [(frame + 0.5) / 10.0 for frame in range(brown.frames)]
    done = subprocess.run(
        [
            node,
            str(HERE / "gltf_three_play.mjs"),
            str(NODE_MODULES),
            str(exported[0]),
            *map(str, times),
        ],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    played = json.loads(done.stdout)
    assert played["duration"] == pytest.approx(brown.frames / 10.0)
    assert played["shown"] == [[f"frame_{frame:05d}"] for frame in range(brown.frames)]
    assert played["meshes"] == 2 * brown.frames  # bell and tentacles per frame


def test_frames_every_and_interpolation_on_the_command_line(
    brown: jellysim.Result, tmp_path: Path
) -> None:
    out = tmp_path / "cli"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "jellysim",
            "export",
            str(brown.folder),
            "--format",
            "gltf",
            "--frames",
            "1:5",
            "--every",
            "2",
            "--interpolation",
            "1",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        check=True,
        timeout=300,
    )
    printed = [Path(line) for line in done.stdout.split()]
    assert printed == [out / "brown-jelly_part000.glb", out / "brown-jelly.gltf-parts.json"]
    glb = Glb(printed[0])
    assert sorted(glb.frame_nodes()) == [1, 3]
    tubes = glb.primitive(glb.frame_nodes()[3], "tentacles")
    assert glb.doc.accessors[tubes.attributes.POSITION].count == 6 * (60 * SIDES + 2)
    times, _ = glb.keyframes(glb.doc.nodes[0].children[-1])
    np.testing.assert_allclose(times, [0.1, 0.3, 0.5])  # shown at 3 / fps, held for --every 2
    index = json.loads(printed[1].read_text())
    assert index["frames"] == {"first": 1, "last": 3, "step": 2, "count": 2}
    assert [(p["first_frame"], p["last_frame"]) for p in index["parts"]] == [(1, 3)]


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (("--frames", "3:1"), "--frames"),
        (("--every", "0"), "--every"),
        (("--interpolation", "0"), "--interpolation"),
    ],
)
def test_bad_gltf_input_exits_2(
    brown: jellysim.Result, tmp_path: Path, args: tuple[str, ...], fragment: str
) -> None:
    out = tmp_path / "nothing"
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "jellysim",
            "export",
            str(brown.folder),
            "--format",
            "gltf",
            "--out",
            str(out),
            *args,
        ],
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
    )
    assert done.returncode == 2
    assert fragment in done.stderr and len(done.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_unknown_format_lists_gltf(brown: jellysim.Result, tmp_path: Path) -> None:
    with pytest.raises(jellysim.InputError, match="gltf"):
        export(brown, "glb", tmp_path)


def test_a_tiny_budget_splits_into_parts_holding_every_frame_once(
    brown: jellysim.Result, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    one_frame = Glb(export(brown, "gltf", tmp_path / "one", frames=(0, 1), interpolation=1)[0])
    frame_size = len(one_frame.blob)
    budget = int(2.5 * frame_size) + gltf_export.JSON_BYTES_FIXED
    monkeypatch.setattr(gltf_export, "PART_BUDGET_BYTES", budget)
    out = tmp_path / "split"
    paths = export(brown, "gltf", out, frames=(0, brown.frames), interpolation=1)
    *parts, index_path = paths
    assert len(parts) >= 2
    assert [p.name for p in parts] == [f"brown-jelly_part{k:03d}.glb" for k in range(len(parts))]
    index = json.loads(index_path.read_text())
    assert index["fps"] == 10.0 and index["frames"]["count"] == brown.frames
    seen: list[int] = []
    for number, (part, entry) in enumerate(zip(parts, index["parts"], strict=True)):
        glb = Glb(part)
        frames = sorted(glb.frame_nodes())
        assert entry["file"] == part.name
        assert frames == list(range(entry["first_frame"], entry["last_frame"] + 1))
        assert entry["frame_count"] == len(frames) and entry["bytes"] == part.stat().st_size
        assert part.stat().st_size <= budget or len(frames) == 1
        assert (glb.doc.asset.extras["part"], glb.doc.asset.extras["parts"]) == (number, len(parts))
        first_times, _ = glb.keyframes(glb.doc.nodes[0].children[0])
        assert first_times[0] == pytest.approx(frames[0] / 10.0)  # absolute times across parts
        seen += frames
    assert seen == list(range(brown.frames))  # every frame in exactly one part, in order
    assert_valid(parts)

    # A later export in fewer parts removes the earlier export's extra parts.
    monkeypatch.setattr(gltf_export, "PART_BUDGET_BYTES", 256 * 2**20)
    (extra := out / "other_part000.glb").write_bytes(b"not ours")
    again = export(brown, "gltf", out, interpolation=1)
    assert sorted(p.name for p in out.iterdir()) == sorted([p.name for p in again] + [extra.name])
    assert not list(out.glob(".*.tmp"))


def test_the_json_allowances_bound_what_a_part_holds(
    brown: jellysim.Result, tmp_path: Path
) -> None:
    def json_length(frames: tuple[int, int]) -> int:
        part = export(brown, "gltf", tmp_path / f"{frames}", frames=frames, interpolation=1)[0]
        return int.from_bytes(part.read_bytes()[12:16], "little")

    one, all_frames = json_length((0, 1)), json_length((0, brown.frames))
    assert one < gltf_export.JSON_BYTES_FIXED
    assert (all_frames - one) / (brown.frames - 1) < gltf_export.JSON_BYTES_PER_FRAME


def test_fluid_particles_are_points(tmp_path: Path) -> None:
    folder = tmp_path / "fluid"
    folder.mkdir()
    rng = np.random.default_rng(7)
    position = rng.uniform(0, 1, (3, 20, 2))
    alive = np.ones((3, 20), dtype=bool)
    alive[1, :4] = False
    alive[2, :] = False  # nothing left to draw at the last frame
    with h5py.File(folder / "result.h5", "w") as f:
        f[fields.TIME.path] = np.array([0.0, 0.1, 0.2])
        f[fields.FLUID_POSITION.path] = position
        f[fields.FLUID_ALIVE.path] = alive
        f[fields.FLUID_KIND.path] = np.zeros(20, dtype=np.int8)
        f.attrs["scene"] = 'name = "block"\n'
        f.attrs["fps"] = 10.0
        f.attrs["frames_expected"] = 3
    with jellysim.open_result(folder) as result:
        paths = export(result, "gltf", tmp_path / "out")
    glb = Glb(paths[0])
    frames = glb.frame_nodes()
    cloud = glb.primitive(frames[1], "fluid")
    assert cloud.mode == 0 and cloud.indices is None  # POINTS
    points = glb.array(cloud.attributes.POSITION)
    assert points.shape == (16, 3)  # dead particles left out
    np.testing.assert_allclose(points[:, :2], position[1, 4:], atol=1e-6)  # 2-D: (x, y, 0)
    assert np.all(points[:, 2] == 0.0)
    assert frames[2].mesh is None  # no live particle: an empty frame
    # The empty frame's node is kept on purpose (each frame has its node, and switching it on
    # hides the frame before): the validator notes it as NODE_EMPTY, an info.
    assert_valid(paths[:1], allowed_infos=("NODE_EMPTY",))


def test_a_single_frame_larger_than_glb_allows_is_refused(
    brown: jellysim.Result, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(gltf_export, "GLB_LIMIT", 1000)
    with pytest.raises(jellysim.JellysimError, match="4 GiB"):
        export(brown, "gltf", tmp_path, frames=(0, 1))
    assert list(tmp_path.iterdir()) == []
