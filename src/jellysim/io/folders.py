"""Output folders: created, or refused with one clear line (exit status 2)."""

from __future__ import annotations

import os
from pathlib import Path

from jellysim.errors import InputError


def output_folder(folder: Path, option: str = "--out") -> Path:
    """Create ``folder`` (and its parents) if need be; raise InputError naming ``option`` when it
    cannot be created or written to."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"{option} {folder}: cannot create the folder ({err.strerror})") from None
    if not os.access(folder, os.W_OK):
        raise InputError(f"{option} {folder}: the folder is not writable")
    return folder
