"""``jellysim export --format gltf``: binary glTF parts read back with pygltflib and compared with
result.h5 (the y-up conversion undone), checked by the Khronos glTF-Validator (zero errors,
warnings, infos and hints) and played by three.js's GLTFLoader and AnimationMixer under Node.js.

Node.js and ``web/node_modules`` (``make web``) are needed for the validator and three.js tests:
skipped without them, except where the environment variable CI is set (CI installs both).
"""

from __future__ import annotations

import importlib.util
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
from jellysim.export.blender_settings import camera_path
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

    def frames(self) -> list[int]:
        """The part's frames: its first (the meshes' own geometry), then one per morph target."""
        first = self.doc.asset.extras["first_frame"]
        mesh = self.doc.meshes[0]
        names = (mesh.extras or {}).get("targetNames", [])
        return [first, *(int(n.removeprefix("frame_")) for n in names)]

    def object(self, name: str) -> tuple[int, pygltflib.Primitive]:
        """The node index and the one primitive of object ``name`` (a child of the root)."""
        root = self.doc.nodes[self.doc.scenes[self.doc.scene].nodes[0]]
        for index in root.children:
            node = self.doc.nodes[index]
            if node.name == name:
                (primitive,) = self.doc.meshes[node.mesh].primitives
                assert self.doc.meshes[node.mesh].name == name
                return index, primitive
        raise KeyError(name)

    def names(self) -> list[str]:
        root = self.doc.nodes[self.doc.scenes[self.doc.scene].nodes[0]]
        return [self.doc.nodes[i].name for i in root.children]

    def at(self, name: str, frame: int, attribute: str = "POSITION") -> np.ndarray:
        """Object ``name``'s ``attribute`` at ``frame``: the base plus that frame's morph target
        (in float64, as a viewer adds them)."""
        _, primitive = self.object(name)
        base = self.array(getattr(primitive.attributes, attribute)).astype(np.float64)
        k = self.frames().index(frame)
        if k == 0:
            return base
        return base + self.array(primitive.targets[k - 1][attribute])

    def material(self, name: str) -> str:
        return self.doc.materials[self.object(name)[1].material].name

    def keyframes(self, node_index: int, path: str) -> tuple[np.ndarray, np.ndarray]:
        (channel,) = [
            c
            for c in self.doc.animations[0].channels
            if c.target.node == node_index and c.target.path == path
        ]
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
    part, index, script = exported
    assert part.name == "brown-jelly_part000.glb" and index.name == "brown-jelly.gltf-parts.json"
    assert script.name == "import_into_blender.py"
    glb = Glb(part)
    assert glb.doc.asset.version == "2.0"
    assert glb.doc.asset.generator == gltf_export.generator()
    # One object each, whatever the frame count: a mesh per part, frames as morph targets.
    assert glb.names() == ["bell", "tentacles"]
    assert len(glb.doc.meshes) == 2 and len(glb.doc.nodes) == 3
    assert glb.frames() == list(range(brown.frames))
    for name in glb.names():
        _, primitive = glb.object(name)
        assert len(primitive.targets) == brown.frames - 1
        assert glb.doc.meshes[glb.doc.nodes[glb.object(name)[0]].mesh].weights == [0.0] * (
            brown.frames - 1
        )
        for target in primitive.targets:  # POSITION deltas carry their bounds
            accessor = glb.doc.accessors[target["POSITION"]]
            delta = glb.array(target["POSITION"])
            assert accessor.min == delta.min(axis=0).tolist()
    drawn = interpolate_result(brown, 2)
    count, particles = 12, 60  # 6 simulated tentacles x 2, 60 particles each
    assert drawn.shape[1:3] == (count, particles)
    radii = tentacle_radii(particles, scene_look(brown.scene))
    faces = brown.file[fields.BELL_SURFACE_FACES.path][:]
    _, bell = glb.object("bell")
    accessor = glb.doc.accessors[bell.attributes.POSITION]
    base = glb.array(bell.attributes.POSITION)
    assert accessor.min == base.min(axis=0).tolist() and accessor.max == base.max(axis=0).tolist()
    triangles = glb.array(bell.indices).reshape(-1, 3)
    np.testing.assert_array_equal(triangles, faces)
    _, tubes = glb.object("tentacles")
    tube_triangles = glb.array(tubes.indices).reshape(-1, 3)
    for frame in (0, 2, brown.frames - 1):
        vertices = glb.at("bell", frame)
        np.testing.assert_allclose(
            z_up(vertices), brown.file[fields.BELL_SURFACE_VERTICES.path][frame], atol=2e-6
        )
        assert signed_volume(vertices, triangles) > 0.0  # winding kept through the rotation
        bell_normals = glb.at("bell", frame, "NORMAL")
        np.testing.assert_allclose(np.linalg.norm(bell_normals, axis=1), 1.0, atol=1e-5)

        points = glb.at("tentacles", frame)
        normals = glb.at("tentacles", frame, "NORMAL")
        assert points.shape == (count * (particles * SIDES + 2), 3)
        np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
        per_tube = z_up(points).reshape(count, particles * SIDES + 2, 3)
        rings = per_tube[:, : particles * SIDES].reshape(count, particles, SIDES, 3)
        np.testing.assert_allclose(rings.mean(axis=2), drawn[frame], atol=2e-6)  # centred
        distance = np.linalg.norm(rings - drawn[frame][:, :, None], axis=-1)
        np.testing.assert_allclose(distance, np.broadcast_to(radii[:, None], distance.shape), 1e-3)
        np.testing.assert_allclose(per_tube[:, -2], drawn[frame][:, 0], atol=2e-6)  # root cap
        np.testing.assert_allclose(per_tube[:, -1], drawn[frame][:, -1], atol=2e-6)  # tip cap
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
    assert [glb.material(name) for name in glb.names()] == ["bell", "tentacles"]
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


def test_animation_morphs_to_one_frame_at_a_time(
    brown: jellysim.Result, exported: list[Path]
) -> None:
    glb = Glb(exported[0])
    fps = 10.0
    samples = (np.arange(brown.frames) + 0.5) / fps  # mid-frame times
    (animation,) = glb.doc.animations
    assert len(animation.samplers) == 1  # one weights sampler, shared by both objects
    for name in glb.names():
        node_index, _ = glb.object(name)
        times, weights = glb.keyframes(node_index, "weights")
        np.testing.assert_array_equal(times, np.float32(np.arange(brown.frames + 1) / fps))
        weights = weights.reshape(len(times), brown.frames - 1)
        assert np.all((weights == 0.0) | (weights == 1.0))
        step = np.searchsorted(times, samples, side="right") - 1
        active = weights[step]  # STEP: the keyframe at or before each sample
        # At frame k's time only target k - 1 (frame k) is on; at frame 0 none (the base).
        expected = np.zeros((brown.frames, brown.frames - 1))
        expected[np.arange(1, brown.frames), np.arange(brown.frames - 1)] = 1.0
        np.testing.assert_array_equal(active, expected)
        np.testing.assert_array_equal(weights[-1], weights[-2])  # the last frame held
    # The animation spans the result: first frame's time to one interval after the last.
    assert times[0] == 0.0 and times[-1] == pytest.approx(brown.frames / fps)
    assert glb.doc.asset.extras["fps"] == fps
    scene_extras = dict(glb.doc.scenes[0].extras)
    settings = scene_extras.pop("jellysim")  # the Blender script's: test_the_blender_script_...
    assert scene_extras == {
        "fps": fps,
        "frame_start": 0,
        "frame_end": brown.frames - 1,
        "frame_step": 1,
    }
    assert (settings["first_frame"], settings["last_frame"], settings["fps"]) == (
        0,
        brown.frames - 1,
        fps,
    )


def _load_script(path: Path):
    spec = importlib.util.spec_from_file_location("import_into_blender", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_blender_script_reads_a_part_s_settings(
    brown: jellysim.Result, exported: list[Path]
) -> None:
    """The exported import_into_blender.py's logic on the part, without Blender (which
    tests/integration/test_blender_import.py runs it in): the settings read from the part's
    scene extras, the frame numbers its keyframes go to, the objects its materials go to."""
    part, _, script_path = exported
    assert script_path.name == "import_into_blender.py"
    script = _load_script(script_path)
    settings = script.read_gltf_settings(part)
    assert settings == script.settings_from_metadata(script.EMBEDDED_SETTINGS)  # the first part
    assert script.stage_path(None, script_path) == part.resolve()
    assert script.load_settings(part) == settings and script.is_gltf(part)
    fps = float(brown.file.attrs["fps"])
    assert (settings["first_frame"], settings["last_frame"], settings["frame_step"]) == (
        0,
        brown.frames - 1,
        1,
    )
    assert settings["fps"] == fps and settings["stage_file"] == part.name
    assert settings["camera_origin"] == camera_path(brown, 2)["camera_origin"]
    # The bounds hold every vertex of every frame (z up).
    glb = Glb(part)
    low, high = np.array(settings["bounds_min"]), np.array(settings["bounds_max"])
    for name in glb.names():
        for frame in glb.frames():
            points = z_up(glb.at(name, frame))
            assert np.all(points >= low - 1e-6) and np.all(points <= high + 1e-6)
    # Blender's importer keys time t at t x its scene's rate: back to the frame numbers, from
    # the file's float32 times, whatever rate it imported at.
    node_index, _ = glb.object("bell")
    times, _ = glb.keyframes(node_index, "weights")
    for rate in (10.0, 24.0, 12.0 * (12.0 / 12.5)):
        keys = [float(t) * rate for t in times]
        assert script.keyframe_frames(keys, fps, rate) == list(range(brown.frames + 1))
    prims = list(script.material_parameters(settings))
    assert script.part_object_prim("bell", prims) == "Bell"
    assert script.part_object_prim("tentacles.001", prims) == "Tentacles"
    assert script.part_object_prim("brown-jelly", prims) is None  # the root node
    assert script.part_object_prim("tentacles_oral-arms", ["Tentacles", "Tentacles_oral_arms"]) == (
        "Tentacles_oral_arms"
    )
    with pytest.raises(script.ScriptError, match="no glTF file at"):
        script.stage_path(part.with_name("missing.glb"), script_path)


def test_the_blender_script_refuses_a_glb_without_settings(tmp_path: Path, exported) -> None:
    script = _load_script(exported[2])
    plain = tmp_path / "plain.gltf"
    plain.write_text(json.dumps({"asset": {"version": "2.0"}, "scenes": [{"nodes": []}]}))
    with pytest.raises(script.ScriptError, match="carries no jellysim settings"):
        script.read_gltf_settings(plain)
    garbage = tmp_path / "garbage.glb"
    garbage.write_bytes(b"glTF\x02\0\0\0\x20\0\0\0\x04\0\0\0BIN\0")
    with pytest.raises(script.ScriptError, match="no JSON chunk"):
        script.read_gltf_settings(garbage)
    garbage.write_bytes(b"not glTF at all")
    with pytest.raises(script.ScriptError, match="is not a glTF file"):
        script.read_gltf_settings(garbage)


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
    assert played["meshes"] == 2  # the bell and the tentacles, whatever the frame count
    for frame, state in enumerate(played["shown"]):
        expected = [] if frame == 0 else [f"frame_{frame:05d}"]
        assert state == {
            "bell": {"targets": expected, "shown": True},
            "tentacles": {"targets": expected, "shown": True},
        }


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
    assert printed == [
        out / "brown-jelly_part000.glb",
        out / "brown-jelly.gltf-parts.json",
        out / "import_into_blender.py",
    ]
    glb = Glb(printed[0])
    assert glb.frames() == [1, 3]
    node_index, tubes = glb.object("tentacles")
    assert glb.doc.accessors[tubes.attributes.POSITION].count == 6 * (60 * SIDES + 2)
    times, weights = glb.keyframes(node_index, "weights")
    np.testing.assert_allclose(times, [0.1, 0.3, 0.5])  # frame 3 at 3 / fps, held for --every 2
    np.testing.assert_array_equal(weights, [0.0, 1.0, 1.0])
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
    *parts, index_path, script = paths
    assert script.name == "import_into_blender.py"
    assert len(parts) >= 2
    assert [p.name for p in parts] == [f"brown-jelly_part{k:03d}.glb" for k in range(len(parts))]
    index = json.loads(index_path.read_text())
    assert index["fps"] == 10.0 and index["frames"]["count"] == brown.frames
    seen: list[int] = []
    for number, (part, entry) in enumerate(zip(parts, index["parts"], strict=True)):
        glb = Glb(part)
        frames = glb.frames()
        assert entry["file"] == part.name
        assert frames == list(range(entry["first_frame"], entry["last_frame"] + 1))
        assert entry["frame_count"] == len(frames) and entry["bytes"] == part.stat().st_size
        assert part.stat().st_size <= budget or len(frames) == 1
        assert (glb.doc.asset.extras["part"], glb.doc.asset.extras["parts"]) == (number, len(parts))
        if len(frames) > 1:
            first_times, _ = glb.keyframes(glb.object("bell")[0], "weights")
            assert first_times[0] == pytest.approx(frames[0] / 10.0)  # absolute times
        else:
            assert glb.doc.animations == []  # a frame alone: nothing to play
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
    assert glb.names() == ["fluid"] and glb.frames() == [0, 1, 2]
    node_index, cloud = glb.object("fluid")
    assert cloud.mode == 0 and cloud.indices is None and cloud.attributes.NORMAL is None  # POINTS
    for frame in range(2):
        points = glb.at("fluid", frame)
        assert points.shape == (20, 3)  # every particle, one vertex count for the morph targets
        live = position[frame, alive[frame]]
        # 2-D: (x, y) lands at (x, y, 0); the live particles where they are, a dead one drawn
        # on the first live one.
        np.testing.assert_allclose(points[alive[frame], :2], live, atol=1e-6)
        np.testing.assert_allclose(
            points[~alive[frame], :2], live[:1].repeat((~alive[frame]).sum(), 0), atol=1e-6
        )
        assert np.all(points[:, 2] == 0.0)
    # No live particle at the last frame: the fluid is scaled to nothing from then on.
    times, scales = glb.keyframes(node_index, "scale")
    np.testing.assert_allclose(times, [0.0, 0.1, 0.2, 0.3], atol=1e-7)
    np.testing.assert_array_equal(scales[:, 0], [1.0, 1.0, 0.0, 0.0])
    assert_valid(paths[:1])


def test_a_part_holds_at_most_morph_frames_max_frames(
    brown: jellysim.Result, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(gltf_export, "MORPH_FRAMES_MAX", 2)
    *parts, index_path, _ = export(brown, "gltf", tmp_path, interpolation=1)
    frames = [Glb(part).frames() for part in parts]
    assert frames == [[0, 1], [2, 3], [4]]
    index = json.loads(index_path.read_text())
    assert [(p["start_time"], p["end_time"]) for p in index["parts"]] == [
        pytest.approx((0.0, 0.2)),
        pytest.approx((0.2, 0.4)),
        pytest.approx((0.4, 0.5)),
    ]
    assert_valid(parts)


def test_a_single_frame_larger_than_glb_allows_is_refused(
    brown: jellysim.Result, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(gltf_export, "GLB_LIMIT", 1000)
    with pytest.raises(jellysim.JellysimError, match="4 GiB"):
        export(brown, "gltf", tmp_path, frames=(0, 1))
    assert list(tmp_path.iterdir()) == []
