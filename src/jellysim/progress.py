"""Progress bars for long work (frames simulated or rendered), on stderr with an ETA."""

from __future__ import annotations

import sys
from typing import Any


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
    already done (a resumed run), shown after ``delay`` seconds; nothing when ``quiet``."""
    if quiet:
        return _NoBar()
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
