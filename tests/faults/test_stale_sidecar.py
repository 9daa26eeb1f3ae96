"""A run killed after its last frame was written but before its closing sidecar write leaves a
complete result beside a sidecar of fewer frames (the writer spaces its sidecar rewrites,
SIDECAR_PAUSE). ``--resume`` finds nothing to simulate and writes the sidecar again, so the
folder ends as an uninterrupted run's (seen in CI: test_kill_moments[tentacles-SIGKILL-0.96],
whose datasets were the reference's bit for bit and whose result.xdmf was not)."""

from __future__ import annotations

import h5py
from faultkit import jellysim_run

from jellysim.io.xdmf import write_xdmf

OVERRIDES = ["duration=1", "fps=10", "tentacles.count=2", "tentacles.particles=10"]


def test_resuming_a_complete_run_rewrites_a_stale_sidecar(tmp_path) -> None:
    out = tmp_path / "run"
    done = jellysim_run(out, OVERRIDES)
    assert done.returncode == 0, done.stderr
    sidecar = out / "result.xdmf"
    whole = sidecar.read_text()
    with h5py.File(out / "result.h5", "r") as f:
        frames = f["time"].shape[0]
        write_xdmf(f, out / "result.h5", sidecar, range(frames - 3))  # the killed run's last
    stale = sidecar.read_text()
    assert stale != whole and stale.count("<Grid ") < whole.count("<Grid ")
    again = jellysim_run(out, OVERRIDES, "--resume")
    assert again.returncode == 0, again.stderr
    assert sidecar.read_text() == whole
