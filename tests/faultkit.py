"""What the tests of runs that stop early share (importable: pytest's pythonpath holds tests/):
the command line, a result's datasets compared bit for bit, and what a folder holds now."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

import jellysim
from jellysim import fields
from jellysim.io.xdmf import XDMF_FILE, xdmf_text

RUNNER = Path(__file__).parent / "faults" / "runner.py"


def sets(overrides: list[str]) -> list[str]:
    return [arg for item in overrides for arg in ("--set", item)]


def run_command(
    out: Path, overrides: list[str], *extra: str, preset: str = "brown-jelly", fault: str = ""
) -> list[str]:
    """``jellysim run`` as a user types it; with ``fault``, through tests/faults/runner.py."""
    head = (
        [sys.executable, str(RUNNER), fault, "--"] if fault else [sys.executable, "-m", "jellysim"]
    )
    return [*head, "run", preset, "--out", str(out), "--quiet", *sets(overrides), *extra]


def jellysim_run(
    out: Path, overrides: list[str], *extra: str, preset: str = "brown-jelly", fault: str = ""
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        run_command(out, overrides, *extra, preset=preset, fault=fault),
        capture_output=True,
        text=True,
        timeout=600,
    )


def datasets(folder: Path) -> dict[str, np.ndarray]:
    found: dict[str, np.ndarray] = {}
    with jellysim.open_result(folder) as r:

        def visit(name: str, obj: object) -> None:
            if isinstance(obj, h5py.Dataset):
                found[name] = obj[()]

        r.file.visititems(visit)
    return found


def attributes(folder: Path) -> dict[str, object]:
    with jellysim.open_result(folder) as r:
        return {k: r.file.attrs[k] for k in r.file.attrs}


def assert_same_result(a: Path, b: Path) -> None:
    """Every dataset and root attribute of the two results equal bit for bit."""
    left, right = datasets(a), datasets(b)
    assert left.keys() == right.keys()
    for name in left:
        assert left[name].dtype == right[name].dtype, name
        # Bit for bit, NaN included (the padding of a group's shorter chains, DESIGN §3).
        assert left[name].shape == right[name].shape, name
        same = (
            np.array_equal(left[name], right[name])
            if left[name].dtype.kind == "O"
            else left[name].tobytes() == right[name].tobytes()
        )
        assert same, f"{name} differs from the reference run"
    assert attributes(a).keys() == attributes(b).keys()
    for key, value in attributes(a).items():
        assert np.array_equal(value, attributes(b)[key]), f"attribute {key} differs"
    # The XDMF sidecars (ParaView's way in) list the same frames of the same datasets.
    assert (a / "result.xdmf").read_text() == (b / "result.xdmf").read_text()


def assert_invalid_input(done: subprocess.CompletedProcess[str]) -> None:
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert 1 <= len(done.stderr.strip().splitlines()) <= 3, done.stderr
    assert done.stdout == ""


def checkpoint_frame(folder: Path) -> int | None:
    try:
        with np.load(folder / "checkpoint.npz") as checkpoint:
            return int(checkpoint["frame"])
    except (OSError, ValueError, KeyError, EOFError):
        return None  # none yet


def written_frames(folder: Path) -> int:
    """The frames on disk now, read as any HDF5 tool would (plain h5py, no jellysim)."""
    try:
        return plain_frames(folder / "result.h5")
    except (OSError, KeyError, ValueError):
        return 0  # no file yet, or the writer is (re)creating it


def plain_frames(path: Path) -> int:
    """Open ``path`` with plain ``h5py.File(path, "r")`` and count the frames as docs/results.md
    tells any reader to: the rows every per-frame dataset holds, up to the first ``time`` that
    is NaN (its fill value: a row a killed flush did not finish) or not later than the one
    before it. Raises what h5py raises when it does not open."""
    with h5py.File(path, "r") as f:
        rows = min(
            int(f[field.path].shape[0])
            for field in fields.FIELDS
            if field.per_frame and field.path in f
        )
        times = f["time"][:rows]
    good = np.isfinite(times)
    good[1:] &= np.diff(times) > 0.0
    return rows if good.all() else int(np.argmin(good))


def one_line(stderr: str) -> str:
    """The single line a failed run prints (no traceback)."""
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    return lines[0]


# A heavy data item of the sidecar: its declared dimensions, and the dataset it names.
_HDF_ITEM = re.compile(r'<DataItem Dimensions="([\d ]+)"([^>]*Format="HDF">result\.h5:)(/[^<]+)<')


def _as_written(text: str, listed: int) -> str:
    """``text`` with every per-frame dataset's declared frame count set to ``listed``."""
    per_frame = {field.path.lstrip("/") for field in fields.FIELDS if field.per_frame}

    def held(match: re.Match[str]) -> str:
        dims = match.group(1).split()
        if match.group(3).lstrip("/") in per_frame:
            dims[0] = str(listed)
        return f'<DataItem Dimensions="{" ".join(dims)}"{match.group(2)}{match.group(3)}<'

    return _HDF_ITEM.sub(held, text)


def sidecar_frames(folder: Path) -> int | None:
    """Check the XDMF sidecar beside ``folder``'s result.h5 against the file, as it is now, and
    return how many frames it lists (None: no sidecar). Whenever it is there it must list a
    prefix of the frames result.h5 holds, at their times, and be the very document the writer
    made of result.h5 when the file held those frames: the document of them today but for the
    frame count each per-frame dataset is declared with (the file has grown since the writer's
    last rewrite, which it spaces out: io/xdmf.py; its hyperslabs still fit, as the datasets only
    grow along frames). ParaView's XDMF reader (VTK's ``vtkXdmfReader``) then reads its last time
    step's points."""
    sidecar = folder / XDMF_FILE
    if not sidecar.exists():
        return None
    xdmf = pytest.importorskip("vtkmodules.vtkIOXdmf2")
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline

    reader = xdmf.vtkXdmfReader()
    reader.SetFileName(str(sidecar))
    reader.UpdateInformation()
    times = reader.GetOutputInformation(0).Get(vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    listed = list(times or ())
    frames = plain_frames(folder / "result.h5")
    assert len(listed) <= frames, f"{XDMF_FILE} lists {len(listed)} frames of {frames}"
    text = sidecar.read_text()
    with h5py.File(folder / "result.h5", "r") as f:
        np.testing.assert_array_equal(listed, f[fields.TIME.path][: len(listed)])
        expected = xdmf_text(f, "result.h5", range(len(listed)))
    assert text == _as_written(text, len(listed)), "a per-frame dataset's declared frames"
    assert text == _as_written(expected, len(listed))
    if listed:
        reader.UpdateTimeStep(listed[-1])
        assert reader.GetOutputDataObject(0).GetNumberOfPoints() > 0
    return len(listed)
