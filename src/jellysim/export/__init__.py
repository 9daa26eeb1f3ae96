"""``jellysim export``: a result as files for other tools, chosen by format name.

Every exporter takes an open result, an output folder, the frames to write and the number of
drawn tentacles per simulated one, and returns the files a user opens first.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from jellysim.errors import InputError
from jellysim.io.folders import output_folder
from jellysim.io.result import Result

Exporter = Callable[[Result, Path, range, "int | None"], list[Path]]


def _vtk(result: Result, out: Path, frames: range, interpolation: int | None) -> list[Path]:
    from jellysim.export.vtk import export_vtk

    return export_vtk(result, out, frames, interpolation)


def _obj(result: Result, out: Path, frames: range, interpolation: int | None) -> list[Path]:
    from jellysim.export.meshes import export_obj

    return export_obj(result, out, frames, interpolation)


def _ply(result: Result, out: Path, frames: range, interpolation: int | None) -> list[Path]:
    from jellysim.export.meshes import export_ply

    return export_ply(result, out, frames, interpolation)


def _usd(result: Result, out: Path, frames: range, interpolation: int | None) -> list[Path]:
    try:
        import pxr  # noqa: F401
    except ImportError:
        raise InputError(
            "--format usd needs usd-core: pip install 'jellysim[usd]' (or pip install usd-core)"
        ) from None
    from jellysim.export.usd import export_usd

    return export_usd(result, out, frames, interpolation)


def _gltf(result: Result, out: Path, frames: range, interpolation: int | None) -> list[Path]:
    from jellysim.export.gltf import export_gltf

    return export_gltf(result, out, frames, interpolation)


def _xdmf(result: Result, out: Path, frames: range, interpolation: int | None) -> list[Path]:
    from jellysim.io.xdmf import XDMF_FILE, write_xdmf

    path = out / XDMF_FILE
    try:
        write_xdmf(result.file, result.path, path, frames)
    except ValueError as err:
        raise InputError(
            f"--out {out}: {err}; choose a folder whose path to {result.path.name} has none "
            f"(inside {result.folder}, for one)"
        ) from None
    except OSError as err:
        raise InputError(f"cannot write '{path}' ({err.strerror or err})") from None
    return [path]


EXPORTERS: dict[str, Exporter] = {
    "vtk": _vtk,
    "obj": _obj,
    "ply": _ply,
    "usd": _usd,
    "gltf": _gltf,
    "xdmf": _xdmf,
}


def export(
    result: Result,
    fmt: str,
    out: str | os.PathLike[str] | None = None,
    frames: tuple[int, int] | None = None,
    every: int = 1,
    interpolation: int | None = None,
    up: str = "y",
) -> list[Path]:
    """Export ``result`` as ``fmt`` into the folder ``out`` (a path, as ``str`` or
    ``os.PathLike``; default ``DIR/export/<fmt>``; for ``xdmf``, ``DIR`` itself: the sidecar
    ``result.xdmf`` that runs write beside ``result.h5``, for a result written before them,
    and only of every frame: a sidecar of some frames goes elsewhere); ``up``: the up axis of
    an OBJ sequence ("y", the OBJ convention, or "z", jellysim's own)."""
    if fmt not in EXPORTERS:
        raise InputError(f"--format {fmt}: unknown; expected one of {', '.join(EXPORTERS)}")
    if fmt == "obj" and up not in ("y", "z"):
        raise InputError(f"--up {up}: expected y or z")
    if every < 1:
        raise InputError(f"--every {every}: expected at least 1")
    if interpolation is not None and not 1 <= interpolation <= 1000:
        raise InputError(f"--interpolation {interpolation}: expected 1 to 1000")
    count = result.frames
    first, stop = (0, count) if frames is None else frames
    if not 0 <= first < stop <= count:
        raise InputError(f"--frames {first}:{stop}: the result has frames 0:{count}")
    selected = range(first, stop, every)
    default = result.folder if fmt == "xdmf" else result.folder / "export" / fmt
    target = Path(out) if out is not None else default
    if fmt == "xdmf" and selected != range(count) and _same_folder(target, result.folder):
        raise InputError(
            f"--frames/--every with --format xdmf would replace {result.folder / 'result.xdmf'}, "
            "the run's sidecar of every frame: name another folder with --out"
        )
    folder = output_folder(target)
    if fmt == "obj":
        from jellysim.export.meshes import export_obj

        return export_obj(result, folder, selected, interpolation, up)
    return EXPORTERS[fmt](result, folder, selected, interpolation)


def _same_folder(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve()
    except OSError:  # a folder that cannot be resolved is no result's folder
        return False
