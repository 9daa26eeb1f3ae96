"""The commands as batch jobs and newcomers meet them (issue 27): ``--quiet`` on every command
that prints, defaults in ``--help``, ``export --format`` in any case, and progress as whole lines
in a log (stderr not a terminal), never carriage returns."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest


def jellysim(*args: str, **env: str) -> subprocess.CompletedProcess[str]:
    variables = {k: v for k, v in os.environ.items() if k != "JELLYSIM_DEBUG"}
    variables.update(env)
    return subprocess.run(
        [sys.executable, "-m", "jellysim", *args],
        capture_output=True,
        text=True,
        timeout=300,
        env={**variables, "COLUMNS": "100"},
    )


@pytest.fixture(scope="module")
def small(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("small")
    done = jellysim(
        "run", "forced-tentacles", "--out", str(folder), "--set", "duration=0.2",
        "--set", "tentacles.count=2", "--set", "solver.dt_safety=0.01",
        JELLYSIM_PROGRESS_DELAY="0",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    # A log, not a terminal: whole lines that name the work and its share, no carriage return.
    assert "\r" not in done.stderr
    assert "simulating: 6/6 frames (100 %)" in done.stderr, done.stderr  # frame 0 is given
    return folder


@pytest.mark.parametrize(
    "command",
    [
        ("plot", "{dir}", "--out", "{tmp}/plots"),
        ("export", "{dir}", "--format", "PLY", "--out", "{tmp}/ply"),
        (
            "sweep",
            "forced-tentacles",
            "--key",
            "flow.speed",
            "--values",
            "0.1,0.3",
            "--set",
            "duration=0.1",
            "--set",
            "tentacles.count=1",
            "--out",
            "{tmp}/sweep",
        ),
    ],  # fmt: skip
    ids=["plot", "export", "sweep"],
)
def test_quiet_prints_nothing_and_writes_the_same(
    small: Path, tmp_path: Path, command: tuple[str, ...]
) -> None:
    args = [a.format(dir=small, tmp=tmp_path) for a in command]
    loud = jellysim(*args)
    assert loud.returncode == 0, loud.stderr
    written = [Path(line) for line in loud.stdout.splitlines()]
    assert written and all(path.exists() for path in written)
    quiet = jellysim(*[a.replace(str(tmp_path), str(tmp_path / "q")) for a in args], "--quiet")
    assert quiet.returncode == 0, quiet.stderr
    assert (quiet.stdout, quiet.stderr) == ("", "")
    for path in written:
        assert Path(str(path).replace(str(tmp_path), str(tmp_path / "q"))).exists()


def test_export_format_is_read_in_any_case(small: Path, tmp_path: Path) -> None:
    done = jellysim("export", str(small), "--format", "Vtk", "--out", str(tmp_path / "vtk"))
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "vtk").is_dir() and any((tmp_path / "vtk").iterdir())


@pytest.mark.parametrize(
    ("command", "shown"),
    [
        ("render", ["picture quality (default: draft)", "(default: 640x480)", "(default: 1)"]),
        ("export", ["every K-th frame (default: 1)", "{vtk,usd,gltf,obj,ply,xdmf}"]),
        ("sweep", ["(default: out/sweeps)"]),
        ("view", ["(default: a free one)"]),
    ],
)
def test_help_shows_the_defaults(command: str, shown: list[str]) -> None:
    done = jellysim(command, "--help")
    assert done.returncode == 0
    text = " ".join(done.stdout.split())  # unwrapped
    for fragment in shown:
        assert fragment in text, (fragment, text)
    assert "(default: None)" not in text and "(default: False)" not in text


def test_a_frame_sequence_export_says_how_many_files(small: Path, tmp_path: Path) -> None:
    done = jellysim(
        "export", str(small), "--format", "obj", "--every", "2", "--out", str(tmp_path / "obj")
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == str(tmp_path / "obj" / "frame_00000.obj")
    assert f"wrote 4 obj files in {tmp_path / 'obj'}" in done.stderr  # frames 0, 2, 4, 6
    assert len(list((tmp_path / "obj").glob("frame_*.obj"))) == 4
