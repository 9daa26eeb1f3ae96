"""Run a reference case and read back everything its result holds, as flat named arrays."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

import jellysim
from jellysim.config.load import same_scene
from regression.cases import CASES

REFERENCE_FOLDER = Path(__file__).resolve().parent / "reference"

# Root attributes that name the software, not the behaviour.
IGNORED_ATTRIBUTES = {"version"}


def run_case(name: str, folder: Path) -> Path:
    """Run case ``name`` into ``folder``; the path of its ``result.h5``."""
    preset, overrides = CASES[name]
    jellysim.run(jellysim.load_scene(preset, overrides), out=folder, force=True).close()
    return folder / "result.h5"


def read_all(path: Path) -> dict[str, np.ndarray]:
    """Every dataset (``data:PATH``), its ``units`` (``units:PATH``) and every root attribute
    (``attr:NAME``) of a result, as arrays."""
    values: dict[str, np.ndarray] = {}
    with h5py.File(path, "r", locking=False) as f:

        def visit(name: str, item: object) -> None:
            if isinstance(item, h5py.Dataset):
                data = np.asarray(item[()])
                if data.dtype == object:  # text (the xyz labels): stored as text, unpickled
                    data = data.astype(str)
                values[f"data:{name}"] = data
                values[f"units:{name}"] = np.asarray(str(item.attrs.get("units", "")))

        f.visititems(visit)
        for key, value in f.attrs.items():
            if key not in IGNORED_ATTRIBUTES:
                array = np.asarray(value)
                if array.dtype == object:  # a list of names (tentacle_groups): stored as text
                    array = array.astype(str)
                values[f"attr:{key}"] = array
    return values


SCENE_ATTRIBUTE = "attr:scene"


def differences(expected: dict[str, np.ndarray], actual: dict[str, np.ndarray]) -> list[str]:
    """What differs, bit for bit (dtype, shape and bytes), one line per array; the scene text
    (``attr:scene``) is compared as the scene it describes
    (:func:`jellysim.config.load.same_scene`: keys added since at their defaults)."""
    lines = [f"missing: {k}" for k in sorted(expected.keys() - actual.keys())]
    lines += [f"new: {k}" for k in sorted(actual.keys() - expected.keys())]
    for key in sorted(expected.keys() & actual.keys()):
        a, b = expected[key], actual[key]
        if key == SCENE_ATTRIBUTE and a.tobytes() != b.tobytes():
            if not same_scene(str(a), str(b)):
                lines.append(f"{key}: describes another scene")
            continue
        if a.dtype != b.dtype or a.shape != b.shape:
            lines.append(f"{key}: {a.dtype}{a.shape} became {b.dtype}{b.shape}")
        elif a.tobytes() != b.tobytes():
            if a.dtype.kind == "f":
                scale = np.nanmax(np.abs(a)) if a.size else 0.0
                gap = np.nanmax(np.abs(a.astype(np.float64) - b)) if a.size else 0.0
                lines.append(f"{key}: differs by up to {gap:.3g} (values up to {scale:.3g})")
            else:
                lines.append(f"{key}: differs in {int(np.sum(a != b))} of {a.size} entries")
    return lines
