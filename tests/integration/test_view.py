"""``jellysim view``: the server's metadata and frame chunks against result.h5 (the drawn tentacles
against :func:`interpolate_result`), only its named routes served, bad input exiting 2, Ctrl-C
exiting 0, and the page itself in headless Chromium (tests/integration/view_e2e.mjs)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import h5py
import numpy as np
import pytest
from viewing import get, serving, status

import jellysim
from jellysim import fields
from jellysim.cli.main import main
from jellysim.errors import InputError
from jellysim.interpolation import interpolate_groups, interpolate_result
from jellysim.render.pipeline import scene_look
from jellysim.view import find_web_modules
from jellysim.view.server import TOKEN_HEADER, WEB_MODULES_ENV, ViewLimits, ViewServer

CHROMIUM = "/usr/bin/chromium"
REPOSITORY = Path(__file__).resolve().parents[2]
FLUID_FRAMES = 10
FLUID_PARTICLES = 120
THREE_PATHS = (
    "/vendor/three/three.module.js",
    "/vendor/three/three.core.js",
    "/vendor/three/OrbitControls.js",
)


@pytest.fixture(scope="module")
def brown(tmp_path_factory: pytest.TempPathFactory) -> Iterator[jellysim.Result]:
    folder = tmp_path_factory.mktemp("brown")
    # brown-jelly's marginal tentacles alone: the one-group viewer (purple below has groups)
    scene = jellysim.load_scene("brown-jelly", {"duration": 0.6, "fps": 20.0}).group_scene(0)
    result = jellysim.run(scene, folder)
    yield result
    result.close()


@pytest.fixture(scope="module")
def fluid(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2-D fluid-only result: a block of particles sliding down, some leaving the domain."""
    folder = tmp_path_factory.mktemp("fluid")
    x, y = np.meshgrid(np.arange(12) * 0.01, np.arange(10) * 0.01 + 0.05)
    block = np.stack([x.ravel(), y.ravel()], axis=1)
    assert block.shape[0] == FLUID_PARTICLES
    position = np.stack([block + [0.01 * f, -0.004 * f] for f in range(FLUID_FRAMES)])
    alive = np.ones((FLUID_FRAMES, FLUID_PARTICLES), dtype=bool)
    alive[4:, :5] = False
    kind = np.zeros(FLUID_PARTICLES, dtype=np.int8)
    kind[-12:] = 1  # a row of wall particles
    with h5py.File(folder / "result.h5", "w") as f:
        f[fields.TIME.path] = np.arange(FLUID_FRAMES) / 10.0
        f[fields.FLUID_POSITION.path] = position
        f[fields.FLUID_ALIVE.path] = alive
        f[fields.FLUID_KIND.path] = kind
        f.attrs["scene"] = 'name = "block"\nfps = 10.0\nduration = 0.9\n'
        f.attrs["fps"] = 10.0
        f.attrs["frames_expected"] = FLUID_FRAMES
        f.attrs["particle_spacing"] = 0.01
    return folder


ARMS_COLOR = (0.0, 0.8, 0.1)  # purple-jelly's oral arms set to a green nothing else has


@pytest.fixture(scope="module")
def purple(tmp_path_factory: pytest.TempPathFactory) -> Iterator[jellysim.Result]:
    """Two tentacle groups: eight marginal threads and four oral arms drawn as ribbons."""
    folder = tmp_path_factory.mktemp("purple")
    result = jellysim.run(
        "purple-jelly",
        folder,
        overrides={"duration": 0.3, "fps": 10.0, "tentacles.oral_arms.color": list(ARMS_COLOR)},
    )
    yield result
    result.close()


@pytest.fixture(scope="module")
def purple_view(purple: jellysim.Result) -> Iterator[ViewServer]:
    with serving(purple.folder) as server:
        yield server


@pytest.fixture(scope="module")
def brown_view(brown: jellysim.Result) -> Iterator[ViewServer]:
    with serving(brown.folder) as server:
        yield server


@pytest.fixture(scope="module")
def fluid_view(fluid: Path) -> Iterator[ViewServer]:
    with serving(fluid) as server:
        yield server


def floats(data: bytes, *shape: int) -> np.ndarray:
    return np.frombuffer(data, dtype="<f4").reshape(shape)


def test_metadata_describes_the_result(brown: jellysim.Result, brown_view: ViewServer) -> None:
    meta = json.loads(get(brown_view, "/meta.json"))
    f = brown.file
    scene = brown.scene
    assert meta["name"] == "brown-jelly"
    assert meta["flow"] == "v = 0.08 m/s"  # the water the tentacles felt, named as the plots do
    assert meta["fps"] == 20.0 and meta["frames"] == brown.frames == 13 and meta["complete"]
    np.testing.assert_array_equal(meta[fields.TIME.path], brown.time)
    look = scene_look(scene)
    assert meta["look"]["bell_color"] == list(look.bell_color)
    assert meta["look"]["tentacle_color"] == list(look.tentacle_color)
    assert meta["look"]["bell_transparency"] == look.bell_transparency
    vertices = f[fields.BELL_SURFACE_VERTICES.path].shape[1]
    assert meta["bell"] == {
        "present": True,
        "vertices": vertices,
        "faces": f[fields.BELL_SURFACE_FACES.path].shape[0],
        "frame_bytes": vertices * 3 * 4,
    }
    assert meta["tentacles"] == {
        "present": True,
        "simulated": 6,
        "particles": scene.tentacles.particles,
        "interpolation": scene.tentacles.interpolation,
        "max_interpolation": 50,
        "frame_bytes": 6 * scene.tentacles.particles * 3 * 4,
    }
    assert meta["fluid"]["present"] is False and meta["fluid"]["frame_bytes"] == 0
    assert meta["limits"] == {
        "max_response_bytes": ViewLimits().max_response_bytes,
        "max_frames_per_request": 256,
        "requests_per_client": ViewLimits().requests_per_client,
    }
    low, high = np.array(meta["bounds"])
    points = np.concatenate(
        [
            f[fields.BELL_SURFACE_VERTICES.path][:].reshape(-1, 3),
            brown.tentacle_positions.reshape(-1, 3),
        ]
    )
    np.testing.assert_allclose(low, points.min(axis=0))
    np.testing.assert_allclose(high, points.max(axis=0))
    assert 0.0 < meta["extent"] <= float((high - low).max())
    assert meta["travels"] is False  # 0.6 s of swimming: less than its size


def test_bell_faces_and_vertices_match_the_result(
    brown: jellysim.Result, brown_view: ViewServer
) -> None:
    f = brown.file
    faces = np.frombuffer(get(brown_view, "/bell-faces"), dtype="<u4").reshape(-1, 3)
    np.testing.assert_array_equal(faces, f[fields.BELL_SURFACE_FACES.path][:])
    vertices = f[fields.BELL_SURFACE_VERTICES.path].shape[1]
    chunk = floats(get(brown_view, "/frames?part=bell&start=3&count=5"), 5, vertices, 3)
    np.testing.assert_allclose(
        chunk, f[fields.BELL_SURFACE_VERTICES.path][3:8], rtol=1e-6, atol=1e-7
    )
    # A chunk reaching past the end stops at the last frame.
    tail = floats(get(brown_view, "/frames?part=bell&start=10&count=16"), 3, vertices, 3)
    np.testing.assert_allclose(
        tail, f[fields.BELL_SURFACE_VERTICES.path][10:], rtol=1e-6, atol=1e-7
    )


@pytest.mark.parametrize("factor", [None, 1, 4])
def test_tentacle_chunks_are_the_drawn_tentacles(
    brown: jellysim.Result, brown_view: ViewServer, factor: int | None
) -> None:
    drawn = interpolate_result(brown, factor)
    count = drawn.shape[1]
    assert count == 6 * (factor or brown.scene.tentacles.interpolation)
    query = "" if factor is None else f"&interpolation={factor}"
    for start, length in ((0, 13), (0, 4), (7, 4), (12, 1)):
        url = f"/frames?part=tentacles&start={start}&count={length}{query}"
        chunk = floats(get(brown_view, url), length, count, brown.scene.tentacles.particles, 3)
        np.testing.assert_allclose(chunk, drawn[start : start + length], rtol=0, atol=1e-6)
    # The simulated tentacles are among them, as simulated.
    every = count // 6
    np.testing.assert_allclose(chunk[:, ::every], brown.tentacle_positions[12:13], atol=1e-6)


def test_groups_are_described_and_sent_each_of_its_own_length(
    purple: jellysim.Result, purple_view: ViewServer
) -> None:
    """meta.json lists the groups; a tentacle frame holds the marginal threads interpolated
    (their own 41 particles) then the four arms as simulated (their own 25), no NaN."""
    meta = json.loads(get(purple_view, "/meta.json"))["tentacles"]
    groups = meta["groups"]
    assert [(g["name"], g["form"], g["particles"], g["simulated"]) for g in groups] == [
        ("marginal", "thread", 41, 8),
        ("oral_arms", "ribbon", 25, 4),
    ]
    assert groups[1]["color"] == list(ARMS_COLOR)
    assert groups[0]["color"] == list(purple.scene.groups[0].tentacles.color)
    assert groups[1]["width"] == purple.scene.groups[1].tentacles.ribbon_width
    assert meta["interpolation"] == 4  # the thread group's own
    factor, count = 3, purple.frames
    body = get(purple_view, f"/frames?part=tentacles&start=0&count={count}&interpolation={factor}")
    threads, arms = 8 * factor * 41 * 3, 4 * 25 * 3
    data = floats(body, count, threads + arms)
    assert np.isfinite(data).all()
    drawn = interpolate_groups(purple, factor)
    np.testing.assert_allclose(
        data[:, :threads], drawn[0].positions.reshape(count, -1), rtol=0, atol=1e-6
    )
    simulated = purple.read(fields.TENTACLE_POSITION)[:, 8:12, :25]
    np.testing.assert_allclose(data[:, threads:], simulated.reshape(count, -1), atol=1e-6)


def test_fluid_chunks_are_world_points_with_dead_particles_nan(
    fluid: Path, fluid_view: ViewServer
) -> None:
    meta = json.loads(get(fluid_view, "/meta.json"))
    assert meta["fluid"] == {
        "present": True,
        "particles": FLUID_PARTICLES,
        "dimensions": 2,
        "radius": pytest.approx(0.005),
        "frame_bytes": FLUID_PARTICLES * 3 * 4,
    }
    assert not meta["bell"]["present"] and not meta["tentacles"]["present"]
    kinds = np.frombuffer(get(fluid_view, "/fluid-kinds"), dtype=np.uint8)
    assert kinds.tolist() == [0] * (FLUID_PARTICLES - 12) + [1] * 12
    chunk = floats(get(fluid_view, "/frames?part=fluid&start=2&count=4"), 4, FLUID_PARTICLES, 3)
    with h5py.File(fluid / "result.h5", "r") as f:
        position, alive = f[fields.FLUID_POSITION.path][2:6], f[fields.FLUID_ALIVE.path][2:6]
    assert np.all(np.isnan(chunk[~alive])) and not np.any(np.isnan(chunk[alive]))
    np.testing.assert_allclose(chunk[alive][:, [0, 2]], position[alive], atol=1e-6)  # (x, 0, y)
    assert np.all(chunk[alive][:, 1] == 0.0)


def test_only_the_named_routes_are_served(brown_view: ViewServer) -> None:
    page = get(brown_view, "/?token=" + brown_view.token).decode("utf-8")
    assert '<script type="importmap">' in page and "/static/viewer.js" in page
    assert brown_view.page_url == f"{brown_view.url}?token={brown_view.token}"
    for path in ("/static/viewer.js", "/static/data.js", "/static/style.css"):
        assert status(brown_view, path) == 200
    for path in THREE_PATHS:
        assert status(brown_view, path) == 200
    for path in (
        "/nothing",
        "/static/../../etc/passwd",
        "/static/%2e%2e/%2e%2e/etc/passwd",
        "/static/..%2f..%2fresult.h5",
        "/static/",
        "/result.h5",
        "/vendor/three/../../package.json",
        "//etc/passwd",
        "/frames/../meta.json",
    ):
        assert status(brown_view, path) == 404, path


@pytest.mark.parametrize(
    ("query", "code"),
    [
        ("part=tentacles&start=0&count=4&interpolation=51", 400),
        ("part=tentacles&start=0&count=4&interpolation=0", 400),
        ("part=bell&start=13&count=1", 400),
        ("part=bell&start=-1&count=1", 400),
        ("part=bell&start=0&count=0", 400),
        ("part=bell&start=0&count=257", 400),
        ("part=bell&start=zero&count=1", 400),
        ("part=mantle&start=0&count=1", 400),
        ("part=fluid&start=0&count=1", 404),
    ],
)
def test_bad_frame_requests(brown_view: ViewServer, query: str, code: int) -> None:
    assert status(brown_view, "/frames?" + query) == code


def test_a_foreign_host_name_is_refused_on_loopback(brown_view: ViewServer) -> None:
    assert status(brown_view, "/meta.json", {"Host": "rebound.example:80"}) == 403
    assert status(brown_view, "/meta.json", {"Host": "localhost:1"}) == 200


def _exit_2(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    assert main(["view", *argv, "--no-browser"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    return err


def test_bad_input_exits_2_with_one_line(
    brown: jellysim.Result, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    assert "not found" in _exit_2(capsys, str(tmp_path / "missing"))
    (tmp_path / "result.h5").write_text("not HDF5")
    assert "not an HDF5 file" in _exit_2(capsys, str(tmp_path))
    assert "--port 70000" in _exit_2(capsys, str(brown.folder), "--port", "70000")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = str(taken.getsockname()[1])
        assert "cannot listen" in _exit_2(capsys, str(brown.folder), "--port", port)
    monkeypatch.setenv(WEB_MODULES_ENV, str(tmp_path))
    assert "three.js not found" in _exit_2(capsys, str(brown.folder))


def test_missing_three_js_says_to_reinstall_or_run_make_web(
    brown: jellysim.Result, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    import jellysim.view.server as server

    modules = tmp_path / "node_modules"
    for part in server.THREE_FILES.values():
        (modules / part).parent.mkdir(parents=True, exist_ok=True)
        (modules / part).write_text("export {};")
    monkeypatch.setenv(WEB_MODULES_ENV, str(modules))
    assert find_web_modules() == modules
    monkeypatch.delenv(WEB_MODULES_ENV, raising=False)
    monkeypatch.setattr(server, "__file__", str(tmp_path / "src" / "jellysim" / "view" / "x.py"))
    with pytest.raises(InputError, match=r"reinstall jellysim.*'make web'.*npm ci"):
        find_web_modules()
    assert "reinstall jellysim" in _exit_2(capsys, str(brown.folder))


def test_the_package_ships_three_js_as_npm_installs_it() -> None:
    """A wheel's viewer needs no checkout and no npm: the package carries three.js (issue 27),
    the same files as ``make web`` installs (web/package.json pins the version)."""
    import json

    import jellysim.view.server as server

    packaged = Path(server.__file__).parent / "vendor"
    assert find_web_modules() == packaged  # what the viewer serves, unless told otherwise
    pinned = json.loads((REPOSITORY / "web" / "package.json").read_text())["dependencies"]["three"]
    assert json.loads((packaged / "three" / "package.json").read_text())["version"] == pinned
    assert (packaged / "three" / "LICENSE").is_file()
    if (REPOSITORY / ".git").exists():  # committed, not only present (.gitignore has bitten)
        listed = subprocess.run(
            ["git", "ls-files", "src/jellysim/view/vendor"],
            cwd=REPOSITORY, capture_output=True, text=True, check=True,
        ).stdout.split()  # fmt: skip
        for part in server.THREE_FILES.values():
            assert f"src/jellysim/view/vendor/{part}" in listed, part
    npm = REPOSITORY / "web" / "node_modules"
    if (npm / "three").is_dir():  # a checkout after make web: the same bytes
        for part in server.THREE_FILES.values():
            assert (packaged / part).read_bytes() == (npm / part).read_bytes(), part


def test_ctrl_c_stops_the_server_with_exit_0(brown: jellysim.Result) -> None:
    env = {k: v for k, v in os.environ.items() if k != "JELLYSIM_DEBUG"}
    source = str(Path(jellysim.__file__).parents[1])  # this checkout's src/, as imported here
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [source, env.get("PYTHONPATH")]))
    # A shell without job control starts background jobs with SIGINT ignored, and Python then
    # installs no KeyboardInterrupt handler: give the server the terminal's default, as Ctrl-C
    # at a prompt would find it.
    process = subprocess.Popen(
        [sys.executable, "-m", "jellysim", "view", str(brown.folder), "--no-browser"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        assert line.startswith(f"jellysim view: serving {brown.folder} at http://127.0.0.1:")
        url = line.split(" at ")[1].split()[0]
        base, token = url.split("?token=")
        with urllib.request.urlopen(url, timeout=30) as page:  # the address printed opens it
            assert b'<script type="importmap">' in page.read()
        meta = urllib.request.Request(base + "meta.json", headers={TOKEN_HEADER: token})
        with urllib.request.urlopen(meta, timeout=30) as answer:
            assert json.loads(answer.read())["frames"] == brown.frames
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0
    assert "Traceback" not in err


def _browser_tools() -> tuple[str, Path] | None:
    node = shutil.which("node")
    modules = REPOSITORY / "web" / "node_modules"  # playwright-core: make web, for the tests
    if node is None or not (modules / "playwright-core").is_dir() or not Path(CHROMIUM).exists():
        return None
    return node, modules


def test_the_page_plays_in_headless_chromium(
    brown: jellysim.Result, brown_view: ViewServer, fluid_view: ViewServer, tmp_path: Path
) -> None:
    """The page plays both results; and a third time the brown jelly, from a server whose
    answers hold at most 3 frames of its largest part and that answers one request at a time
    per client, its only slot held by another request when the page starts: the page fetches
    every part in several pieces within the limit, waits out the 429 and plays through."""
    tools = _browser_tools()
    if tools is None:
        if os.environ.get("CI"):
            pytest.fail("the viewer test needs node, web/node_modules and chromium (make test)")
        pytest.skip("node, web/node_modules (make web) or chromium (make chromium) missing")
    node, modules = tools
    script = Path(__file__).with_name("view_e2e.mjs")
    meta = json.loads(get(brown_view, "/meta.json"))
    factor = brown.scene.tentacles.interpolation
    frame_bytes = {
        "bell": meta["bell"]["frame_bytes"],
        "tentacles": meta["tentacles"]["frame_bytes"] * max(factor, 3),  # the page's factors
    }
    small = ViewLimits(max_response_bytes=3 * max(frame_bytes.values()), requests_per_client=1)
    with serving(brown.folder, small) as pieces:
        holder = threading.Thread(target=_hold_a_slot, args=(pieces,), daemon=True)
        holder.start()
        urls = [view.page_url for view in (brown_view, fluid_view, pieces)]
        done = subprocess.run(
            [node, str(script), str(modules), CHROMIUM, str(tmp_path), *urls],
            capture_output=True,
            text=True,
            timeout=180,
        )
        holder.join(10)
        assert pieces.budget.refused >= 1
    assert done.returncode == 0, done.stdout + done.stderr
    pages = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    assert len(pages) == 3
    jelly, block, pieced = pages
    for page in pages:
        assert page["advanced"] and page["wrapped"] > page["frames"] // 2
    assert jelly["pixelsChanged"] and pieced["pixelsChanged"]
    assert jelly["drawnTentacles"] == [6 * factor, 6 * 3]
    assert block["fluidPoints"][0] > 0 and block["fluidPoints"][1] == 0
    for page in pages:
        assert Path(page["screenshot"]).stat().st_size > 5000
    # Default limits: one piece per part and factor for 13 frames, no 429.
    assert jelly["busy"] == 0 and len(jelly["answers"]["bell"]) == 1
    # Small limits: several pieces, none over the limit, and the page waited out a 429.
    assert pieced["busy"] >= 1
    for part in ("bell", "tentacles"):
        sizes = pieced["answers"][part]
        assert max(sizes) <= small.max_response_bytes, (part, sizes)
    largest = max(frame_bytes, key=frame_bytes.__getitem__)
    assert len(pieced["answers"][largest]) >= 4, pieced["answers"]


def test_the_page_draws_each_group_in_its_colour(
    purple: jellysim.Result, purple_view: ViewServer, tmp_path: Path
) -> None:
    """The purple jelly plays in headless Chromium (view_e2e.mjs's checks, the drawn count by
    group), and its screenshot shows the arms' green, which nothing else in the picture has."""
    from PIL import Image

    tools = _browser_tools()
    if tools is None:
        if os.environ.get("CI"):
            pytest.fail("the viewer test needs node, web/node_modules and chromium (make test)")
        pytest.skip("node, web/node_modules (make web) or chromium (make chromium) missing")
    node, modules = tools
    script = Path(__file__).with_name("view_e2e.mjs")
    done = subprocess.run(
        [node, str(script), str(modules), CHROMIUM, str(tmp_path), purple_view.page_url],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    (page,) = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    # 8 x 4 threads (the preset's interpolation) and 4 arms, then 8 x 3 threads and the same 4.
    assert page["drawnTentacles"] == [8 * 4 + 4, 8 * 3 + 4]
    pixels = np.asarray(Image.open(page["screenshot"]).convert("RGB")).astype(np.int64)
    r, g, b = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    green = (g > 60) & (g > 2 * r) & (g > 2 * b)
    assert green.sum() > 200, green.sum()


def _hold_a_slot(server: ViewServer) -> None:
    """Hold the one slot of 127.0.0.1 (as another tab's request would) until the server has
    turned a request away, or for 120 s at most."""
    with server.budget.slot("127.0.0.1") as granted:
        assert granted
        deadline = time.monotonic() + 120
        while server.budget.refused == 0 and time.monotonic() < deadline:
            time.sleep(0.02)
