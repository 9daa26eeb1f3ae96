"""Every command as a user runs it (``python -m jellysim`` and the ``jellysim`` script), the
Python API, and a short run of every preset (DESIGN §3, STYLE rule 10)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import h5py
import matplotlib.image
import numpy as np
import pytest
from scenes import SMALL_FINE

import jellysim
from jellysim import fields

QUICK = ["duration=0.5", "tentacles.count=2", "tentacles.particles=20"]
# About 240 frames of some 1,600 substeps: a few seconds, long enough for the bar to update.
LONG = [
    "duration=8",
    "tentacles.count=2",
    "tentacles.particles=20",
    "solver.dt_safety=0.003",
]


def _script() -> str:
    found = shutil.which("jellysim", path=str(Path(sys.executable).parent)) or shutil.which(
        "jellysim"
    )
    assert found, "the 'jellysim' console script is not installed next to the interpreter"
    return found


INVOKERS = {
    "module": lambda: [sys.executable, "-m", "jellysim"],
    "script": lambda: [_script()],
}


def _sets(overrides: list[str]) -> list[str]:
    return [arg for item in overrides for arg in ("--set", item)]


def _cli(
    *args: str, cwd: Path | None = None, how: str = "module"
) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k != "JELLYSIM_DEBUG"}
    return subprocess.run(
        [*INVOKERS[how](), *args], capture_output=True, text=True, timeout=300, cwd=cwd, env=env
    )


def _assert_invalid_input(done: subprocess.CompletedProcess[str]) -> None:
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert 1 <= len(done.stderr.strip().splitlines()) <= 3, done.stderr


def _frames(folder: Path) -> int:
    with jellysim.open_result(folder) as r:
        return r.frames


@pytest.mark.parametrize("how", INVOKERS)
def test_version(how: str) -> None:
    done = _cli("--version", how=how)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == f"jellysim {jellysim.__version__}"


@pytest.mark.parametrize("how", INVOKERS)
def test_presets_lists_every_preset(how: str) -> None:
    done = _cli("presets", how=how)
    assert done.returncode == 0, done.stderr
    listed = [line.split()[0] for line in done.stdout.splitlines() if line.strip()]
    assert "brown-jelly" in listed
    assert listed == jellysim.preset_names()
    brown = next(line for line in done.stdout.splitlines() if line.startswith("brown-jelly"))
    assert len(brown.split()) > 1, "a preset is listed with its one-line summary"


@pytest.mark.parametrize("how", INVOKERS)
def test_show_prints_toml_that_runs(tmp_path: Path, how: str) -> None:
    done = _cli("show", "brown-jelly", how=how)
    assert done.returncode == 0, done.stderr
    tree = tomllib.loads(done.stdout)
    assert tree["name"] == "brown-jelly"
    assert jellysim.load_scene(tree) == jellysim.load_scene("brown-jelly")

    scene_file = tmp_path / "mine.toml"
    scene_file.write_text(done.stdout, encoding="utf-8")
    out = tmp_path / "out"
    ran = _cli("run", str(scene_file), "--out", str(out), "--quiet", *_sets(QUICK), how=how)
    assert ran.returncode == 0, ran.stderr
    assert _frames(out) == jellysim.load_scene(scene_file, QUICK).frame_count


def test_show_unknown_preset_exits_2() -> None:
    done = _cli("show", "brown-jely")
    _assert_invalid_input(done)
    assert "brown-jelly" in done.stderr  # the suggestion
    assert done.stdout == ""


@pytest.fixture(scope="module")
def ran(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, subprocess.CompletedProcess[str]]:
    """``jellysim run brown-jelly`` without --out, from an empty working folder."""
    cwd = tmp_path_factory.mktemp("cwd")
    return cwd, _cli("run", "brown-jelly", "--quiet", *_sets(QUICK), cwd=cwd)


def test_run_writes_result_and_scene(ran: tuple[Path, subprocess.CompletedProcess[str]]) -> None:
    cwd, done = ran
    assert done.returncode == 0, done.stderr
    assert done.stdout == "" and done.stderr == ""  # --quiet
    folder = cwd / "out" / "brown-jelly"  # the default DIR: out/<scene name>
    assert (folder / "result.h5").is_file()
    assert not (folder / "checkpoint.npz").exists()
    expected = jellysim.load_scene("brown-jelly", QUICK)
    assert jellysim.load_scene(folder / "scene.toml") == expected
    with jellysim.open_result(folder) as r:
        assert r.frames == expected.frame_count and r.complete
        assert r.scene == expected
        assert np.all(np.isfinite(r.tentacle_positions))
    with h5py.File(folder / "result.h5", "r") as f:  # closed cleanly: any HDF5 reader opens it
        assert f[fields.TIME.path].shape == (expected.frame_count,)


def test_plot_writes_nontrivial_pngs(ran: tuple[Path, subprocess.CompletedProcess[str]]) -> None:
    cwd, _ = ran
    folder = cwd / "out" / "brown-jelly"
    done = _cli("plot", str(folder))
    assert done.returncode == 0, done.stderr
    paths = [Path(line) for line in done.stdout.splitlines() if line.strip()]
    assert paths, "plot printed no file names"
    assert {p.parent for p in paths} == {folder / "plots"}
    for path in paths:
        assert path.suffix == ".png" and path.is_file()
        assert path.stat().st_size > 10_000, f"{path.name} is only {path.stat().st_size} bytes"
        image = matplotlib.image.imread(path)
        pixels = image.reshape(-1, image.shape[-1]) if image.ndim == 3 else image.reshape(-1, 1)
        assert len(np.unique(pixels, axis=0)) > 10, f"{path.name} is (nearly) a single colour"
        background = np.all(pixels == pixels[0], axis=1)
        assert background.mean() < 0.99, f"{path.name} is almost empty"


def test_plot_without_result_exits_2(tmp_path: Path) -> None:
    _assert_invalid_input(_cli("plot", str(tmp_path)))
    assert not (tmp_path / "plots").exists()


def test_force_replaces_a_result(tmp_path: Path) -> None:
    out = tmp_path / "run"
    first = _cli("run", "brown-jelly", "--out", str(out), "--quiet", *_sets(QUICK))
    assert first.returncode == 0, first.stderr
    assert _frames(out) == 16
    before = (out / "result.h5").read_bytes()

    longer = [*QUICK, "duration=1"]
    refused = _cli("run", "brown-jelly", "--out", str(out), "--quiet", *_sets(longer))
    _assert_invalid_input(refused)
    assert "--force" in refused.stderr
    assert (out / "result.h5").read_bytes() == before

    forced = _cli("run", "brown-jelly", "--out", str(out), "--quiet", "--force", *_sets(longer))
    assert forced.returncode == 0, forced.stderr
    assert _frames(out) == 31
    assert jellysim.load_scene(out / "scene.toml") == jellysim.load_scene("brown-jelly", longer)


def test_invalid_set_exits_2_and_writes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "never"
    for bad, key in [
        # the shared count reaches the marginal group (the oral arms set their own): its name
        ("tentacles.count=0", "tentacles.marginal.count"),
        ("tentacles.bending=ewnig", "tentacles.bending"),
        ("tentacles.colour=red", "tentacles.colour"),
    ]:
        done = _cli("run", "brown-jelly", "--out", str(out), "--set", bad)
        _assert_invalid_input(done)
        assert key in done.stderr
        assert not out.exists()


def test_progress_bar_and_quiet(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # The bar waits 2 s before it appears; a fast machine finishes LONG sooner than that.
    monkeypatch.setenv("JELLYSIM_PROGRESS_DELAY", "0")
    loud = _cli("run", "brown-jelly", "--out", str(tmp_path / "loud"), *_sets(LONG))
    assert loud.returncode == 0, loud.stderr
    assert "simulating" in loud.stderr and "%" in loud.stderr, loud.stderr[-2000:]
    assert "result.h5" in loud.stdout

    quiet = _cli("run", "brown-jelly", "--out", str(tmp_path / "quiet"), "--quiet", *_sets(LONG))
    assert quiet.returncode == 0, quiet.stderr
    assert quiet.stdout == "" and quiet.stderr == ""
    with (
        jellysim.open_result(tmp_path / "loud") as a,
        jellysim.open_result(tmp_path / "quiet") as b,
    ):
        assert np.array_equal(a.tentacle_positions, b.tentacle_positions)


# --- Python API ------------------------------------------------------------------------------


def test_api_overrides_as_dict_and_as_strings(tmp_path: Path) -> None:
    as_dict = jellysim.load_scene(
        "brown-jelly",
        {"tentacles.youngs_modulus": 2.4e5, "tentacles.root": "pinned", "duration": 0.5},
    )
    as_strings = jellysim.load_scene(
        "brown-jelly", ["tentacles.youngs_modulus=2.4e5", "tentacles.root=pinned", "duration=0.5"]
    )
    assert as_dict == as_strings
    assert as_dict.tentacles.youngs_modulus == 2.4e5
    assert as_dict.tentacles.root == "pinned"
    assert as_dict.duration == 0.5
    assert as_dict.tentacles.count == jellysim.load_scene("brown-jelly").tentacles.count

    path = tmp_path / "scene.toml"
    path.write_text(jellysim.scene_to_toml(as_dict), encoding="utf-8")
    assert jellysim.load_scene(path) == as_dict
    assert jellysim.load_scene(str(path)) == as_dict
    with pytest.raises(jellysim.InputError, match=r"tentacles\.marginal\.count = 0"):
        jellysim.load_scene("brown-jelly", {"tentacles.count": 0})  # the arms set their own


def test_api_run_and_open_result(tmp_path: Path) -> None:
    scene = jellysim.load_scene("brown-jelly", QUICK)
    result = jellysim.run(scene, tmp_path / "a")
    assert isinstance(result, jellysim.Result)
    with result:
        assert result.frames == scene.frame_count
    assert not result.file.id.valid  # the context manager closed it

    # The same run from a preset name with overrides as a mapping.
    overrides = dict(jellysim.config.parse_override(item) for item in QUICK)
    jellysim.run("brown-jelly", tmp_path / "b", overrides=overrides).close()
    with jellysim.open_result(tmp_path / "a") as a, jellysim.open_result(tmp_path / "b") as b:
        assert a.scene == b.scene == scene
        assert np.array_equal(a.tentacle_positions, b.tentacle_positions)
        # the two marginal tentacles, then the four oral arms (which set their own count)
        assert a.tentacle_positions.shape == (scene.frame_count, 2 + 4, 20, 3)
        assert a.time.shape == a.rim.shape[:1] == a.margin.shape[:1] == (scene.frame_count,)
        handle = a.file
    assert not handle.id.valid

    with jellysim.open_result(tmp_path / "a" / "result.h5") as direct:
        assert direct.frames == scene.frame_count
    with pytest.raises(jellysim.InputError, match="exists"):
        jellysim.run(scene, tmp_path / "a")
    with pytest.raises(jellysim.InputError):
        jellysim.open_result(tmp_path / "nowhere")


# Presets run here on a smaller scene: moon-jelly-fine's 1.5 million water particles take 13-27 s
# a step on 2 cores and 40 steps for 0.1 s; its lattice and six-particle wall run on a small bell
# (tests/scenes.py), its own size in tests/unit/test_moon_jelly_fine.py (built, not stepped).
SHRUNK: dict[str, dict[str, object]] = {"moon-jelly-fine": SMALL_FINE}


@pytest.mark.parametrize("name", jellysim.preset_names())
def test_every_preset_runs(tmp_path: Path, name: str) -> None:
    scene = jellysim.load_scene(name, {**SHRUNK.get(name, {}), "duration": 0.1})
    with jellysim.run(scene, tmp_path) as r:
        assert r.frames == scene.frame_count >= 2
        assert r.scene == scene
        float_data: list[str] = []

        def check(path: str, obj: object) -> None:
            if isinstance(obj, h5py.Dataset) and np.issubdtype(obj.dtype, np.floating):
                float_data.append(path)
                values = obj[()]
                if path in ("tentacles/position", "tentacles/velocity"):
                    # Shorter chains of a group are NaN-padded beyond their own particles
                    # (docs/groups.md); their own rows must be finite.
                    own = r.tentacle_particles
                    rows = np.arange(values.shape[2])[None, :] < own[:, None]  # (T, P)
                    assert np.all(np.isnan(values[:, ~rows])), f"{name}: {path} padding"
                    values = values[:, rows]
                assert np.all(np.isfinite(values)), f"{name}: {path} holds non-finite values"

        r.file.visititems(check)
        assert "time" in float_data and len(float_data) > 1
