"""`jellysim sweep` as a user runs it."""

import csv
import subprocess
import sys

import matplotlib.image


def jellysim(cwd, *args):
    return subprocess.run(
        [sys.executable, "-m", "jellysim", *args], cwd=cwd, capture_output=True, text=True
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
    assert proc.stdout.split() == ["figs/sweep_flow_speed.png", "figs/sweep_flow_speed.csv"]
    image = matplotlib.image.imread(png)
    assert image.shape[0] > 300 and image.std() > 0.05
    with open(table, newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 2 * 31
    assert {float(row["flow.speed"]) for row in rows} == {0.0, 0.5}
    assert float(rows[0]["root_x_m"]) == 0.15


def test_sweep_rejects_bad_values_before_writing(tmp_path):
    for args in (("--key", "flow.sped", "--values", "1"), ("--key", "flow.speed", "--values", ",")):
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
