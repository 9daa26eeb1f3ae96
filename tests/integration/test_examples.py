"""The Python examples in examples/ run as documented (issue 27: a parameter study, and reading
results into xarray and pandas), on short runs, and write and print what they say."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def run(script: str, *args: str, cwd: Path) -> str:
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / script), *args],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=cwd,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_the_stiffness_study_writes_one_row_per_modulus(tmp_path: Path) -> None:
    out = tmp_path / "study.csv"
    printed = run("stiffness_study.py", str(out), "--duration", "1", cwd=tmp_path)
    assert printed.strip().endswith(str(out))
    rows = list(csv.DictReader(out.open()))
    assert [float(r["youngs_modulus_Pa"]) for r in rows] == [100.0, 1e3, 1e4, 2.4e5]
    for row in rows:
        assert 0.9 < float(row["chord_per_length"]) <= 1.0
        assert float(row["tip_x_range_m"]) > 0.0


def test_reading_results_into_xarray_and_pandas(tmp_path: Path) -> None:
    printed = run("read_results.py", cwd=tmp_path)
    assert (tmp_path / "out" / "read_results" / "result.h5").exists()
    lines = printed.splitlines()
    assert lines[0].startswith("brown-jelly: 31 frames, groups ['marginal', 'oral_arms']")
    assert "mean" in lines[1] and "max" in lines[1]
    assert len(lines) == 3 + 10  # header lines, then one row per tentacle (6 + 4)
