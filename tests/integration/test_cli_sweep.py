"""`jellysim sweep` as a user runs it."""

import csv
import os
import subprocess
import sys

import matplotlib.image

from jellysim.simulation.run import COMPILE_NOTICE


def jellysim(cwd, *args):
    # A scheduler that does not answer is given up after a second, not Dask's 30.
    env = {**os.environ, "DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "1s"}
    return subprocess.run(
        [sys.executable, "-m", "jellysim", *args], cwd=cwd, capture_output=True, text=True, env=env
    )


def test_sweep_writes_a_labelled_figure_and_the_traces(tmp_path):
    proc = jellysim(
        tmp_path,
        "sweep",
        "brown-jelly",
        "--key",
        "flow.speed",
        "--values",
        "0,0.5",
        "--set",
        "duration=1",
        "--set",
        "tentacles.count=1",
        "--out",
        "figs",
    )
    assert proc.returncode == 0, proc.stderr
    png = tmp_path / "figs" / "sweep_flow_speed.png"
    table = tmp_path / "figs" / "sweep_flow_speed.csv"
    assert proc.stdout.split() == [
        "figs/sweep_flow_speed.png",
        "figs/sweep_flow_speed.csv",
        "figs/sweep_flow_speed_points.csv",
        "figs/sweep_flow_speed.nc",
    ]
    image = matplotlib.image.imread(png)
    assert image.shape[0] > 300 and image.std() > 0.05
    with open(table, newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 2 * 31
    assert {float(row["flow.speed"]) for row in rows} == {0.0, 0.5}
    assert float(rows[0]["root_x_m"]) == 0.15


def test_sweep_rejects_bad_values_before_writing(tmp_path):
    for args in (
        ("--key", "flow.sped", "--values", "1"),
        ("--key", "flow.speed", "--values", ","),
        ("--vary", "flow.speed=0,1", "--vary", "tentacles.count=1,2,3", "--zip"),
        ("--vary", "flow.speed"),
        ("--vary", "flow.speed=1", "--workers", "0"),
        ("--vary", "flow.speed=1", "--scheduler", "not-an-address"),
        ("--vary", "flow.speed=1", "--scheduler", "tcp://127.0.0.1:9"),  # nothing listens
        ("--vary", "flow.speed=0,0.0"),  # one point twice (one scene)
    ):
        proc = jellysim(tmp_path, "sweep", "brown-jelly", *args, "--out", "figs")
        assert proc.returncode == 2
        assert len(proc.stderr.strip().splitlines()) <= 3 and "Traceback" not in proc.stderr
        assert not (tmp_path / "figs").exists()


def test_an_unreadable_value_is_named_as_the_values_option(tmp_path):
    """The error names --values, not an internal key (issue 24)."""
    proc = jellysim(tmp_path, "sweep", "brown-jelly", "--key", "duration", "--values", "a b,[1,")
    assert proc.returncode == 2
    assert proc.stderr.strip() == (
        "jellysim: error: --values: cannot read the value 'a b' as a TOML value"
    )


def test_a_point_that_fails_is_one_line_and_its_status(tmp_path):
    """A point the worker refuses (its run would not fit on the disk) ends the sweep with that
    point named and its exit status; the other points are kept for the next run."""
    proc = jellysim(
        tmp_path,
        "sweep",
        "brown-jelly",
        "--vary",
        "duration=0.1,1e6",
        "--set",
        "tentacles.count=1",
        "--out",
        "figs",
        "--quiet",
    )
    assert proc.returncode == 2
    (line,) = proc.stderr.strip().splitlines()
    assert line.startswith("jellysim: error: point 1 (duration = 1e+06): the run would write")
    assert "run the sweep again to continue" in line
    assert len(list((tmp_path / "figs" / "points").glob("*/result.h5"))) == 1
    assert not list((tmp_path / "figs").glob("sweep_*"))


def test_a_duplicate_point_is_named(tmp_path):
    proc = jellysim(tmp_path, "sweep", "brown-jelly", "--vary", "flow.speed=0.5,1,0.5")
    assert proc.returncode == 2
    assert proc.stderr.strip() == (
        "jellysim: error: points 0 (flow.speed = 0.5) and 2 (flow.speed = 0.5) are the same "
        "scene: give each point once"
    )


def test_a_sweep_that_compiles_gives_the_notice_once_and_quiet_none(tmp_path):
    """Issue 27's compile notice in a sweep whose two workers both compile (an empty Numba
    cache): once for the sweep, not once per worker; with --quiet, nothing."""
    sweep = ["sweep", "brown-jelly", "--vary", "flow.speed=0,0.5", "--workers", "2"]
    tiny = ["--set", "tentacles.count=1", "--set", "duration=0.1"]
    for quiet, notices in ((False, 1), (True, 0)):
        env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / f"cache-{quiet}")}
        proc = subprocess.run(
            [sys.executable, "-m", "jellysim", *sweep, *tiny, "--out", f"s-{quiet}"]
            + ["--quiet"] * quiet,
            cwd=tmp_path,
            capture_output=True,
            text=True,
            env=env,
            timeout=600,
        )
        assert proc.returncode == 0, proc.stderr
        assert proc.stderr.count(COMPILE_NOTICE) == notices, proc.stderr
        if quiet:
            assert proc.stderr == ""
