"""Issue 27: the first run on a machine compiles the kernels (10 to 60 s); it says so in one line,
from the command line and from the API, instead of leaving the user in silence. ``--quiet`` (and
``quiet=True``) says nothing; a run whose kernels come from Numba's cache says nothing either.

Each case runs with its own empty Numba cache (``NUMBA_CACHE_DIR``), so it compiles whatever
the other tests have cached; a case that only needs to see the notice stops the run once it has.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from jellysim.simulation.run import COMPILE_NOTICE

TINY = ["--set", "duration=0.1"]
API = (
    "import sys, jellysim\n"
    "jellysim.run('brown-jelly', sys.argv[1], overrides={'duration': 0.1}, force=True)\n"
)


def _environment(cache: Path) -> dict[str, str]:
    return {**os.environ, "NUMBA_CACHE_DIR": str(cache)}


def _first_lines_until_notice(command: list[str], cache: Path) -> list[str]:
    """Start ``command``; return its stderr lines up to the notice, then stop it (or all of
    them, if it ends without one)."""
    process = subprocess.Popen(
        command,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=_environment(cache),
    )
    assert process.stderr is not None
    lines = []
    try:
        for line in process.stderr:
            lines.append(line.rstrip("\n"))
            if COMPILE_NOTICE in line:
                break
    finally:
        process.kill()
        process.wait(timeout=60)
    return lines


def _cli(out: Path, *extra: str) -> list[str]:
    return [
        sys.executable,
        "-m",
        "jellysim",
        "run",
        "brown-jelly",
        "--out",
        str(out),
        *TINY,
        *extra,
    ]


def test_a_first_command_line_run_says_it_compiles(tmp_path: Path) -> None:
    lines = _first_lines_until_notice(_cli(tmp_path / "run"), tmp_path / "cache")
    assert lines and lines[-1] == COMPILE_NOTICE, lines
    assert not any("Traceback" in line for line in lines), lines


def test_a_first_api_run_says_it_compiles(tmp_path: Path) -> None:
    """``jellysim.run`` with its defaults: no progress bar, but the notice (on stderr, with no
    logging set up by the caller)."""
    command = [sys.executable, "-c", API, str(tmp_path / "run")]
    lines = _first_lines_until_notice(command, tmp_path / "cache")
    assert lines == [COMPILE_NOTICE], lines


@pytest.fixture(scope="module")
def warm_cache(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """A cache filled by one quiet run from empty; that run's stderr."""
    folder = tmp_path_factory.mktemp("compile")
    done = subprocess.run(
        _cli(folder / "quiet", "--quiet"),
        capture_output=True,
        text=True,
        env=_environment(folder / "cache"),
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    return folder / "cache", done.stderr


def test_quiet_says_nothing_even_while_it_compiles(warm_cache: tuple[Path, str]) -> None:
    _, stderr = warm_cache
    assert stderr == ""


def test_a_run_with_cached_kernels_says_nothing_of_compiling(
    warm_cache: tuple[Path, str], tmp_path: Path
) -> None:
    cache, _ = warm_cache
    done = subprocess.run(
        _cli(tmp_path / "run"), capture_output=True, text=True, env=_environment(cache), timeout=600
    )
    assert done.returncode == 0, done.stderr
    assert "compiled kernels ready in" in done.stderr, done.stderr
    assert COMPILE_NOTICE not in done.stderr, done.stderr
