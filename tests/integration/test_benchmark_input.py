"""The benchmarks take scenes and ``--set KEY=VALUE`` as ``jellysim run`` does, and treat bad
input as it does: exit status 2, one line on stderr naming the key or the preset, no traceback
(DESIGN §3; ``benchmarks/_input.py``). Each case fails at the scene, before any simulation."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"

# (script, arguments, a text its one line must contain)
CASES = [
    ("bench_moon.py", ("--set", "fluid.bogus=1", "--steps", "1"), "fluid.bogus"),
    ("bench_moon.py", ("--preset", "no-such-jelly", "--steps", "1"), "no-such-jelly"),
    ("bench_fluid.py", ("--case", "tank-3d", "--set", "fluid.bogus=1"), "fluid.bogus"),
    ("bell_pulses.py", ("--full", "--set", "bell.bogus=1"), "bell.bogus"),
    ("bench_lions_mane.py", ("--set", "tentacles.bogus=1"), "tentacles.bogus"),
    ("motion_report.py", ("brown-jelly", "--set", "flow.bogus=1"), "flow.bogus"),
    ("swim_with_tentacles.py", ("--set", "bell.radius=-1"), "bell.radius"),
    ("parallel_regions.py", ("--set", "fluid.bogus=1", "--steps", "1"), "fluid.bogus"),
    ("parallel_regions.py", ("--case", "no-such-case"), "no-such-case"),
]


@pytest.mark.parametrize(("script", "args", "named"), CASES)
def test_bad_input_to_a_benchmark_is_one_line_and_exit_2(
    script: str, args: tuple[str, ...], named: str, tmp_path: Path
) -> None:
    if script == "parallel_regions.py" and not (shutil.which("cc") or shutil.which("gcc")):
        pytest.skip("parallel_regions.py builds its counter with a C compiler; none here")
    proc = subprocess.run(
        [sys.executable, str(BENCHMARKS / script), *args, *out_of(script, tmp_path)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"{script}: error: ") and named in lines[0], lines[0]
    assert list(tmp_path.iterdir()) == []  # nothing written: no output folder, no partial run


def out_of(script: str, tmp_path: Path) -> tuple[str, ...]:
    """The output folder of the scripts that take one, under ``tmp_path``."""
    takes = ("bell_pulses.py", "motion_report.py")
    return ("--out", str(tmp_path / "out")) if script in takes else ()
