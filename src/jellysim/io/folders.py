"""Output folders: created, or refused with one clear line (exit status 2)."""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
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


def check_writable(folder: Path, option: str = "--out") -> None:
    """Refuse, creating nothing, an output whose nearest existing folder cannot be written to
    (a read-only file system, no permission) or is a file."""
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(f"{option} {folder}: '{existing}' exists and is not a folder")
    if not os.access(existing, os.W_OK):
        reason = "a read-only file system" if _read_only(existing) else "no permission"
        raise InputError(f"{option} {folder}: the folder is not writable ({reason})")


def _read_only(path: Path) -> bool:
    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except OSError:
        return False


@contextmanager
def writing_lock(folder: Path) -> Iterator[None]:
    """Hold ``folder``'s writer lock while the block runs: one jellysim run writes a folder at a
    time. The lock is an flock on the folder itself, so no file is left behind, and the kernel
    releases it when the process ends, killed or not. Raises InputError if another run holds it.
    """
    descriptor = os.open(folder, os.O_RDONLY)
    try:
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(
                f"'{folder}' is being written by another jellysim run: wait for it to end, "
                "or choose another --out"
            ) from None
        yield
    finally:
        os.close(descriptor)  # releases the lock
