"""Invalid input on the real command line: exit status 2, at most three lines naming the key and
the value, no traceback, and nothing written (DESIGN §3)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from jellysim.cli.main import main

PRESET = "brown-jelly"
TINY = ("--set", "duration=0.1", "--quiet")  # a valid run of four frames


def jellysim(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k != "JELLYSIM_DEBUG"}
    env["COLUMNS"] = "80"  # argparse wraps its usage at the terminal width
    return subprocess.run(
        [sys.executable, "-m", "jellysim", *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def snapshot(folder: Path) -> dict[str, bytes | None]:
    """Every path under ``folder`` with its bytes (None for folders)."""
    return {
        str(p.relative_to(folder)): None if p.is_dir() else p.read_bytes()
        for p in sorted(folder.rglob("*"))
    }


def assert_rejected(
    status: int, stdout: str, stderr: str, named: tuple[str, ...], out: Path
) -> None:
    lines = stderr.strip().splitlines()
    assert status == 2, stderr
    assert 1 <= len(lines) <= 3, stderr
    assert "Traceback" not in stderr
    for text in named:
        assert text in stderr, f"{text!r} not in {stderr!r}"
    assert stdout == ""
    assert not out.exists(), f"{out} was written"


def check_subprocess(tmp_path: Path, args: tuple[str, ...], named: tuple[str, ...]) -> None:
    before = snapshot(tmp_path)
    proc = jellysim(tmp_path, *args, "--out", "out")
    assert_rejected(proc.returncode, proc.stdout, proc.stderr, named, tmp_path / "out")
    assert snapshot(tmp_path) == before


# (arguments after 'run', texts that stderr must contain)
SET_CASES = {
    "unknown-key": (("--set", "durtion=2"), ("durtion", "did you mean 'duration'")),
    "unknown-nested-key": (("--set", "tentacles.cout=3"), ("tentacles.cout", "'count'")),
    "unknown-table": (("--set", "tentacle.count=3"), ("tentacle", "did you mean 'tentacles'")),
    "string-for-number": (("--set", "tentacles.spacing=abc"), ("tentacles.spacing", "'abc'")),
    "float-for-int": (("--set", "tentacles.count=2.5"), ("tentacles.count = 2.5", "integer")),
    "gravity-of-two": (("--set", "water.gravity=[0, -9.81]"), ("water.gravity", "[0, -9.81]")),
    "bool-for-float": (("--set", "water.density=true"), ("water.density = true",)),
    "too-few-particles": (("--set", "tentacles.particles=2"), ("tentacles.particles = 2", ">= 3")),
    "bad-choice": (("--set", "tentacles.bending=ewin"), ("tentacles.bending", "'ewing'")),
    "huge-int": (("--set", "seed=" + "9" * 30), ("seed", "9" * 30)),
    "set-without-equals": (("--set", "duration"), ("duration", "KEY=VALUE")),
    "set-a-table": (("--set", "tentacles=3"), ("tentacles", "table")),
    "set-below-a-value": (("--set", "duration.x=3"), ("duration", "not a table")),
    "unreadable-value": (("--set", "duration=1.2.3"), ("duration", "1.2.3")),
    "nothing-to-resume": (("--resume",), ("nothing to resume", "result.h5")),
    "force-and-resume": (("--force", "--resume"), ("--force", "--resume")),
    # brown-jelly's shared curl reaches its marginal group (its oral arms set their own), and
    # the message names the group's key.
    "curl-too-tight": (
        ("--set", "tentacles.rest_curvature=80"),
        ("tentacles.marginal.rest_curvature = 80", "tentacles.marginal.spacing", "at most 0.5"),
    ),
    "torsion-too-tight": (
        ("--set", "tentacles.rest_torsion=-80"),
        ("tentacles.marginal.rest_torsion = -80", "at most 0.5"),
    ),
    # Issue 26: a current needs a direction; drag laws and coefficients are checked.
    "zero-current-direction": (
        ("--set", "flow.model=current", "--set", "flow.direction=[0, 0, 0]"),
        ("flow.direction", "no direction"),
    ),
    "unknown-flow-model": (("--set", "flow.model=currant"), ("flow.model", "'current'")),
    "fluid-flow-without-fluid": (
        ("--set", "flow.model=fluid"),
        ("flow.model = 'fluid'", "has none", "fluid.model = 'mps'"),
    ),
    "two-way-without-fluid": (
        ("--set", "flow.two_way=true"),
        ("flow.two_way = true", "flow.model = 'fluid'"),
    ),
    "unknown-drag-law": (("--set", "tentacles.drag=cylinder"), ("tentacles.drag", "'slender'")),
    "negative-drag-coefficient": (
        ("--set", "tentacles.normal_drag=-1"),
        ("tentacles.normal_drag = -1", ">= 0"),
    ),
    "huge-tangential-coefficient": (
        ("--set", "tentacles.tangential_drag=5"),
        ("tentacles.tangential_drag = 5", "<= 1"),
    ),
}


@pytest.mark.parametrize(("args", "named"), SET_CASES.values(), ids=SET_CASES)
def test_bad_option(tmp_path: Path, args: tuple[str, ...], named: tuple[str, ...]) -> None:
    check_subprocess(tmp_path, ("run", PRESET, *args), named)


# Tentacle groups (issue 25), on a preset with two: marginal and oral_arms.
GROUPED = "purple-jelly"
GROUP_CASES = {
    "unknown-group": (
        ("--set", "tentacles.oral_armz.count=3"),
        ("tentacles.oral_armz.count", "unknown tentacle group 'oral_armz'", "oral_arms"),
    ),
    "group-without-roots": (
        ("--set", "tentacles.oral_arms.count=0"),
        ("tentacles.oral_arms.count = 0", "no roots"),
    ),
    "arms-too-wide": (
        ("--set", "tentacles.oral_arms.mouth_radius=0.95"),
        ("tentacles.oral_arms.mouth_radius", "do not fit under the bell"),
    ),
    "group-curl-too-tight": (
        ("--set", "tentacles.marginal.rest_curvature=80"),
        ("tentacles.marginal.rest_curvature = 80", "at most 0.5"),
    ),
    "shared-key-every-group-sets": (
        ("--set", "tentacles.count=3"),
        ("tentacles.count", "every tentacle group sets count"),
    ),
    "unknown-key-in-group": (
        ("--set", "tentacles.marginal.cout=3"),
        ("tentacles.marginal.cout", "did you mean 'count'"),
    ),
}


# Obstacles and probes (issue 28, SPHERIC Test 2), on the preset that has them.
SPHERIC = "spheric-test2"
PROBE_CASES = {
    "obstacle-outside-the-tank": (
        ("--set", "fluid.obstacles=[[3.0, 0.3, 0.0, 3.5, 0.7, 0.161]]"),
        ("fluid.obstacles[0] = [3.0, 0.3, 0.0, 3.5, 0.7, 0.161]", "not inside the tank"),
    ),
    "obstacle-in-the-water": (
        ("--set", "fluid.obstacles=[[2.5, 0.3, 0.0, 2.8, 0.7, 0.161]]"),
        ("fluid.obstacles[0]", "overlaps the water"),
    ),
    "obstacle-upside-down": (
        ("--set", "fluid.obstacles=[[0.8, 0.3, 0.0, 0.6, 0.7, 0.161]]"),
        ("fluid.obstacles = [[0.8, 0.3, 0.0, 0.6, 0.7, 0.161]]", "x0 < x1"),
    ),
    "obstacle-too-thin": (
        ("--set", "fluid.obstacles=[[0.6, 0.3, 0.0, 0.62, 0.7, 0.161]]"),
        ("fluid.obstacles[0]", "too thin"),
    ),
    "height-probe-outside": (
        ("--set", "probes.height.H2=[4.0, 0.5]"),
        ("probes.height.H2 = [4.0, 0.5]", "not inside the tank"),
    ),
    "height-probe-in-3-d": (
        ("--set", "probes.height.H2=[1.0, 0.5, 0.2]"),
        ("probes.height.H2", "expected 2 coordinates"),
    ),
    "pressure-probe-in-the-water": (
        ("--set", "probes.pressure.P1=[1.5, 0.5, 0.3]"),
        ("probes.pressure.P1 = [1.5, 0.5, 0.3]", "not on a wall"),
    ),
    "pressure-probe-outside": (
        ("--set", "probes.pressure.P1=[0.8245, 1.5, 0.021]"),
        ("probes.pressure.P1", "not on a wall"),
    ),
    "probe-not-a-table": (
        ("--set", "probes.pressure=[1, 2, 3]"),
        ("probes.pressure = [1, 2, 3]", "NAME = [x, ...]"),
    ),
    "obstacles-in-2-d": (
        (
            "--set",
            "fluid.dimensions=2",
            "--set",
            "fluid.lattice=hexagonal",
            "--set",
            "water.gravity=[0, -9.81, 0]",
        ),
        ("fluid.obstacles", "3-D fluid-only scenes"),
    ),
}


@pytest.mark.parametrize(("args", "named"), PROBE_CASES.values(), ids=PROBE_CASES)
def test_bad_obstacle_or_probe(
    tmp_path: Path, args: tuple[str, ...], named: tuple[str, ...]
) -> None:
    check_subprocess(tmp_path, ("run", SPHERIC, *args), named)


@pytest.mark.parametrize(("args", "named"), GROUP_CASES.values(), ids=GROUP_CASES)
def test_bad_group_option(tmp_path: Path, args: tuple[str, ...], named: tuple[str, ...]) -> None:
    check_subprocess(tmp_path, ("run", GROUPED, *args), named)


def test_set_names_no_group_in_a_one_table_scene(tmp_path: Path) -> None:
    check_subprocess(
        tmp_path,
        ("run", "forced-tentacles", "--set", "tentacles.arms.count=4"),
        ("tentacles.arms.count", "no tentacle group 'arms'"),
    )


# (file name, its TOML text or None for a folder, texts that stderr must contain)
FILE_CASES = {
    "group-named-like-a-key": (
        "scene.toml",
        "[tentacles.count]\nparticles = 3\n",
        ("tentacles.count", "not a group"),
    ),
    "nested-group": (
        "scene.toml",
        "[tentacles.arms]\ncount = 2\n[tentacles.arms.tips]\ncount = 1\n",
        ("tentacles.arms.tips", "do not nest"),
    ),
    "angles-for-another-count": (
        "scene.toml",
        "[tentacles.arms]\ncount = 3\nangles = [0.0, 90.0]\n",
        ("tentacles.arms.angles", "2 angles", "count = 3"),
    ),
    "unknown-nested-key": (
        "scene.toml",
        "[tentacles]\ncout = 3\n",
        ("tentacles.cout", "did you mean 'count'"),
    ),
    "unknown-table": ("scene.toml", "[tentcles]\ncount = 3\n", ("tentcles", "'tentacles'")),
    "unknown-top-level-key": ("scene.toml", "fsp = 30\n", ("fsp", "did you mean 'fps'")),
    "string-for-number": ("scene.toml", '[water]\ndensity = "heavy"\n', ("water.density",)),
    "table-as-value": ("scene.toml", "tentacles = 3\n", ("tentacles", "table")),
    "syntax-error": ("bad.toml", "duration = 1\nfps = = 3\n", ("bad.toml", "line 2")),
    "syntax-error-at-end": ("bad.toml", "[water]\ngravity = [0, 0,\n", ("bad.toml", "line 2")),
    "not-utf8": ("latin.toml", b'name = "caf\xe9"\n', ("latin.toml",)),
    "directory": ("dir.toml", None, ("dir.toml",)),
    "binary": ("blob.toml", b"\x00\x01name = 1\n", ("blob.toml", "not a scene file", "binary")),
    "huge": ("huge.toml", b"# " + b"x" * (1 << 20) + b"\n", ("huge.toml", "larger than 1 MiB")),
}


@pytest.mark.parametrize(("name", "content", "named"), FILE_CASES.values(), ids=FILE_CASES)
def test_bad_scene_file(
    tmp_path: Path, name: str, content: str | bytes | None, named: tuple[str, ...]
) -> None:
    path = tmp_path / name
    if content is None:
        path.mkdir()
    elif isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8")
    check_subprocess(tmp_path, ("run", name), named)


def test_an_endless_input_is_not_a_scene_file(tmp_path: Path) -> None:
    """/dev/zero is read no further than a scene file's largest size (issue 24)."""
    check_subprocess(tmp_path, ("run", "/dev/zero"), ("/dev/zero", "not a scene file"))


def test_missing_scene_file(tmp_path: Path) -> None:
    check_subprocess(tmp_path, ("run", "missing.toml"), ("missing.toml", "No such file"))


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root reads any file")
def test_unreadable_scene_file(tmp_path: Path) -> None:
    path = tmp_path / "secret.toml"
    path.write_text("duration = 1\n", encoding="utf-8")
    path.chmod(0)
    try:
        check_subprocess(tmp_path, ("run", "secret.toml"), ("secret.toml", "ermission"))
    finally:
        path.chmod(0o600)


def test_unknown_preset(tmp_path: Path) -> None:
    check_subprocess(tmp_path, ("run", "brown-jely"), ("brown-jely", "did you mean 'brown-jelly'"))


def test_override_below_a_table_written_as_a_value(tmp_path: Path) -> None:
    (tmp_path / "scene.toml").write_text("tentacles = 3\n", encoding="utf-8")
    check_subprocess(
        tmp_path, ("run", "scene.toml", "--set", "tentacles.count=2"), ("tentacles", "table")
    )


# Out-of-range numbers: in process (the same main() the subprocesses run; start-up costs ~1 s).
BOUNDED_KEYS = (
    "tentacles.spacing",
    "tentacles.youngs_modulus",
    "water.density",
    "tentacles.density",
    "duration",
)


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf", "-inf"])
@pytest.mark.parametrize("key", BOUNDED_KEYS)
def test_out_of_range_number(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    key: str,
    value: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    status = main(["run", PRESET, "--set", f"{key}={value}", "--out", "out"])
    captured = capsys.readouterr()
    assert_rejected(
        status, captured.out, captured.err, (f"{key} = {value}", "expected"), tmp_path / "out"
    )
    assert list(tmp_path.iterdir()) == []


EXTREME_CASES = {
    "tiny-spacing": ("tentacles.spacing=1e-300", "tentacles.spacing"),
    "dense-water": ("water.density=1e300", "water.density"),
    "thin-water": ("water.density=1e-300", "water.density"),
    "syrup": ("water.viscosity=1e300", "water.viscosity"),
    "no-viscosity": ("water.viscosity=1e-300", "water.viscosity"),
    "supersonic-flow": ("flow.speed=1e300", "flow.speed"),
    "tiny-safety": ("solver.dt_safety=1e-300", "solver.dt_safety"),
    "huge-fps": ("fps=1e300", "fps"),
    "huge-bell": ("bell.radius=1e300", "bell.radius"),
    "white-noise": ("flow.noise_correlation_time=1e-300", "flow.noise_correlation_time"),
    "buzzing-root": ("root_motion.frequency=1e9", "root_motion.frequency"),
    "dots-name": ('name=".."', "name"),
}


@pytest.mark.parametrize(("item", "key"), EXTREME_CASES.values(), ids=EXTREME_CASES)
def test_extreme_finite_values_are_input_errors(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    item: str,
    key: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    status = main(["run", PRESET, "--set", item, "--out", "out"])
    captured = capsys.readouterr()
    assert_rejected(status, captured.out, captured.err, (key,), tmp_path / "out")
    assert list(tmp_path.iterdir()) == []


def test_a_scene_that_needs_too_many_substeps_is_refused_before_writing(tmp_path: Path) -> None:
    args = (
        "run",
        PRESET,
        "--set",
        "tentacles.youngs_modulus=1e13",
        "--set",
        "fps=0.01",
        "--set",
        "tentacles.particles=3",
        "--set",
        "duration=100",
    )
    check_subprocess(tmp_path, args, ("substeps per frame", "solver.dt_safety"))


@pytest.mark.parametrize("key", BOUNDED_KEYS)
def test_out_of_range_number_subprocess(tmp_path: Path, key: str) -> None:
    check_subprocess(tmp_path, ("run", PRESET, "--set", f"{key}=nan"), (f"{key} = nan",))


def test_out_is_a_file(tmp_path: Path) -> None:
    (tmp_path / "out").write_text("mine\n", encoding="utf-8")
    before = snapshot(tmp_path)
    proc = jellysim(tmp_path, "run", PRESET, *TINY, "--out", "out")
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.strip().splitlines()) <= 3
    assert "Traceback" not in proc.stderr and "out" in proc.stderr
    assert snapshot(tmp_path) == before


def test_existing_result_is_not_overwritten(tmp_path: Path) -> None:
    first = jellysim(tmp_path, "run", PRESET, *TINY, "--out", "out")
    assert first.returncode == 0, first.stderr
    result = tmp_path / "out" / "result.h5"
    assert result.is_file()
    before = snapshot(tmp_path)
    mtime = result.stat().st_mtime_ns

    again = jellysim(tmp_path, "run", PRESET, *TINY, "--out", "out")
    assert again.returncode == 2, again.stderr
    assert len(again.stderr.strip().splitlines()) <= 3
    assert "Traceback" not in again.stderr
    assert "result.h5" in again.stderr and "--force" in again.stderr
    assert snapshot(tmp_path) == before
    assert result.stat().st_mtime_ns == mtime


def test_argparse_errors_fit_three_lines(tmp_path: Path) -> None:
    proc = jellysim(tmp_path, "run", "--out", "out")
    assert_rejected(proc.returncode, proc.stdout, proc.stderr, ("scene",), tmp_path / "out")


def test_mixed_source_without_the_corrected_gradient_is_refused(tmp_path: Path) -> None:
    """The mixed source is unstable with the standard gradient (docs/fluid.md): refused before
    anything is written, naming the key to set."""
    check_subprocess(
        tmp_path,
        ("run", "dam-break-2d", "--set", "fluid.gradient=standard"),
        ("fluid.source = 'mixed'", "fluid.gradient = 'corrected'"),
    )


def test_conservative_gradient_with_the_surface_repulsion_is_refused(tmp_path: Path) -> None:
    """The surface repulsion pushes one particle of a pair only, which would undo what the
    conservative gradient conserves: refused before anything is written, naming both keys."""
    gradient = "fluid.gradient=conservative"
    check_subprocess(
        tmp_path,
        ("run", "hydrostatic-2d", "--set", "fluid.source=standard", "--set", gradient),
        ("fluid.gradient = 'conservative'", "fluid.surface_repulsion"),
    )


def test_hexagonal_lattice_in_three_dimensions_is_refused(tmp_path: Path) -> None:
    """The hexagonal lattice is 2-D only: refused before anything is written."""
    check_subprocess(
        tmp_path,
        ("run", "tank-3d", "--set", "fluid.lattice=hexagonal"),
        ("fluid.lattice = 'hexagonal' is 2-D only",),
    )


def test_fcc_lattice_in_two_dimensions_is_refused(tmp_path: Path) -> None:
    """The face-centred cubic lattice is 3-D only: refused before anything is written."""
    check_subprocess(
        tmp_path,
        ("run", "hydrostatic-2d", "--set", "fluid.lattice=fcc"),
        ("fluid.lattice = 'fcc' is 3-D only", "'hexagonal'"),
    )


def test_soft_bell_on_the_fcc_lattice_is_refused(tmp_path: Path) -> None:
    """The mass-spring bell is carved out of the cubic lattice: refused on the fcc one."""
    check_subprocess(
        tmp_path,
        ("run", "moon-jelly", "--set", "fluid.lattice=fcc"),
        ("fluid.lattice = 'fcc'", "fluid.lattice = 'square'"),
    )


def test_either_density_surface_without_the_mixed_source_is_refused(tmp_path: Path) -> None:
    """The either-density surface also tests n at the start of the step, which only the mixed
    source computes: refused before anything is written, naming the key to set."""
    check_subprocess(
        tmp_path,
        (
            "run", "hydrostatic-2d", "--set", "fluid.surface=either-density",
            "--set", "fluid.source=standard", "--set", "fluid.gradient=standard",
        ),
        ("fluid.surface = 'either-density'", "fluid.source = 'mixed'"),
    )  # fmt: skip


def test_a_result_without_frames_is_refused_by_its_readers(tmp_path: Path) -> None:
    """A run stopped before its first frame reached the disk (issue 24): plot, render, export
    and view say so in one line (exit 2) instead of failing inside."""
    from jellysim.config import load_scene
    from jellysim.io.result import ResultWriter
    from jellysim.simulation import make_loop

    loop = make_loop(load_scene(PRESET, {"duration": 0.1}))
    folder = tmp_path / "empty"
    folder.mkdir()
    ResultWriter(folder / "result.h5", loop.datasets(), loop.attributes("")).close()
    for args in (
        ("plot", "empty"),
        ("render", "empty", "--quality", "draft"),
        ("export", "empty", "--format", "obj"),
        ("view", "empty", "--no-browser"),
    ):
        proc = jellysim(tmp_path, *args)
        assert proc.returncode == 2, (args, proc.stderr)
        assert "holds no frames" in proc.stderr and "Traceback" not in proc.stderr, args
        assert len(proc.stderr.strip().splitlines()) <= 3
