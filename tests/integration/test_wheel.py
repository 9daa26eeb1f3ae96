"""``pip install jellysim`` gives a working ``jellysim view`` (issue 27): the wheel built from
this checkout, installed into a fresh virtual environment with no checkout and no npm, serves
the viewer's page and its three.js.

The wheel is built offline (``--no-build-isolation``; setuptools and wheel are test extras) from
a copy of the sources, and installed ``--no-deps --no-index``; the fresh environment borrows the
dependencies (NumPy, Numba, h5py, ...) from the test's own environment through a path file, which
adds their folder but not the editable checkout (a path file's folders have their own path files
ignored), so ``jellysim`` comes from the wheel alone (checked).
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import site
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest

import jellysim
from jellysim.view.server import THREE_FILES, TOKEN_HEADER

REPOSITORY = Path(__file__).resolve().parents[2]
PACKAGE = REPOSITORY / "src" / "jellysim"


def _packaged(route: str) -> str:
    """Where the package keeps the file the viewer serves at ``route``."""
    if route in THREE_FILES:
        return f"vendor/{THREE_FILES[route]}"
    return route.lstrip("/")


@pytest.fixture(scope="module")
def fresh(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh virtual environment with the wheel installed: its bin/ folder."""
    root = tmp_path_factory.mktemp("wheel")
    source = root / "source"
    shutil.copytree(
        REPOSITORY / "src",
        source / "src",
        ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "*.nbi", "*.nbc"),
    )
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(REPOSITORY / name, source / name)
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    built = subprocess.run(
        [*pip, "wheel", "--no-deps", "--no-build-isolation", "-w", str(root / "dist"), str(source)],
        capture_output=True,
        text=True,
    )
    assert built.returncode == 0, built.stdout + built.stderr
    (wheel,) = (root / "dist").glob("jellysim-*.whl")
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    purelib = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    installed = subprocess.run(
        [*pip, "install", "--no-deps", "--no-index", "--target", purelib, str(wheel)],
        capture_output=True,
        text=True,
    )
    assert installed.returncode == 0, installed.stderr
    # The dependencies, from this environment's site-packages (not the editable jellysim).
    Path(purelib, "test-dependencies.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    where = subprocess.run(
        [str(python), "-c", "import jellysim; print(jellysim.__file__)"],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    assert Path(where).is_relative_to(venv), where  # the wheel's, not the checkout's
    # The console script the wheel declares, written as pip writes one (``--target`` puts
    # scripts beside the packages, not in the environment's bin/).
    (entry_points,) = Path(purelib).glob("jellysim-*.dist-info/entry_points.txt")
    assert "jellysim = jellysim.cli.main:main" in entry_points.read_text()
    (venv / "bin" / "jellysim").write_text(
        f"#!{python}\nfrom jellysim.cli.main import main\nraise SystemExit(main())\n"
    )
    (venv / "bin" / "jellysim").chmod(0o755)
    return venv / "bin"


def test_the_installed_wheel_serves_the_viewer_and_its_three_js(
    fresh: Path, tmp_path: Path
) -> None:
    scene = jellysim.load_scene("forced-tentacles", {"duration": 0.2, "tentacles.count": 2})
    jellysim.run(scene, tmp_path / "result").close()
    env = {k: v for k, v in os.environ.items() if k not in ("JELLYSIM_WEB_MODULES", "PYTHONPATH")}
    process = subprocess.Popen(
        [str(fresh / "jellysim"), "view", str(tmp_path / "result"), "--no-browser"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=tmp_path,  # no checkout here
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        match = re.search(r"(http://127\.0\.0\.1:\d+)/\?token=(\S+)", line)
        assert match, line + (process.stderr.read() if process.poll() is not None else "")
        base, token = match.groups()
        page = urllib.request.urlopen(f"{base}/?token={token}", timeout=30).read().decode()
        assert "viewer.js" in page
        # Everything the page loads, from the installed wheel alone.
        for route in (*THREE_FILES, "/static/viewer.js", "/static/data.js", "/static/style.css"):
            request = urllib.request.Request(f"{base}{route}", headers={TOKEN_HEADER: token})
            with urllib.request.urlopen(request, timeout=30) as response:
                assert response.status == 200, route
                served = response.read()
            # The package's own file, whole (three.js included: no checkout, no npm).
            assert served == (PACKAGE / "view" / _packaged(route)).read_bytes(), route
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    assert process.returncode == 0
