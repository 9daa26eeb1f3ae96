"""Progress bars for long work (frames simulated or rendered), on stderr with an ETA."""

from __future__ import annotations

import os
import sys
from typing import Any

DELAY_ENV = "JELLYSIM_PROGRESS_DELAY"  # seconds before a bar appears, overriding each caller's


class _NoBar:
    """Stands in for a bar when output is quiet."""

    def __enter__(self) -> _NoBar:
        return self

    def __exit__(self, *args: object) -> None:
        return None

    def update(self, n: int) -> None:
        return None


def progress(total: int, done: int, quiet: bool, what: str, delay: float = 0.0) -> Any:
    """A context manager with ``update(n)``: a tqdm bar of ``total`` frames, ``done`` of them
    already done (a resumed run), shown after ``delay`` seconds (``$JELLYSIM_PROGRESS_DELAY``
    when set to a number of seconds); nothing when ``quiet``."""
    if quiet:
        return _NoBar()
    delay = _delay_from_environment(delay)
    from tqdm import tqdm

    return tqdm(
        total=total,
        initial=done,
        unit="frame",
        delay=delay,
        file=sys.stderr,
        dynamic_ncols=True,
        desc=what,
    )


def _delay_from_environment(default: float) -> float:
    """``$JELLYSIM_PROGRESS_DELAY`` as seconds (0 shows every bar at once), else ``default``;
    a value that is not a number, or is negative, is ignored."""
    try:
        value = float(os.environ[DELAY_ENV])
    except (KeyError, ValueError):
        return default
    return value if value >= 0 else default
