"""Progress for long work (frames simulated or rendered), on stderr with an ETA: a bar on a
terminal, plain lines in a log (a batch job's, CI's: stderr not a terminal), where a bar's
carriage-return updates would make one endless line."""

from __future__ import annotations

import math
import os
import sys
import time
from typing import Any, TextIO

DELAY_ENV = "JELLYSIM_PROGRESS_DELAY"  # seconds before a bar appears, overriding each caller's
LOG_STEPS = 20  # in a log, a line each time another 5 % of the work is done,
LOG_INTERVAL = 60.0  # and at least one a minute (seconds) while work goes on


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
    if not _is_terminal(sys.stderr):
        return LogLines(total, done, what, delay, sys.stderr)
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


def _is_terminal(stream: TextIO) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError):  # a replaced or closed stream
        return False


class LogLines:
    """Progress as whole lines, for a log: ``what: done/total frames (p %), elapsed, about
    remaining left``, the first once ``delay`` s have passed, then one each time another
    1 / ``LOG_STEPS`` of the work is done or ``LOG_INTERVAL`` s have passed without a line, and the
    last when the work is done."""

    def __init__(self, total: int, done: int, what: str, delay: float, stream: TextIO) -> None:
        self.total, self.done, self.what = total, done, what
        self.delay, self.stream = delay, stream
        self._start_done = done
        self._start = time.monotonic()
        self._last = -math.inf
        self._shown = done

    def __enter__(self) -> LogLines:
        return self

    def __exit__(self, *args: object) -> None:
        if self._last > -math.inf and self._shown != self.done:
            self._write(time.monotonic())

    def update(self, n: int) -> None:
        self.done += n
        now = time.monotonic()
        if now - self._start < self.delay:
            return
        step = self.done * LOG_STEPS // self.total if self.total else 0
        shown = self._shown * LOG_STEPS // self.total if self.total else 0
        first = self._last == -math.inf
        if first or step > shown or now - self._last >= LOG_INTERVAL or self.done >= self.total:
            self._write(now)

    def _write(self, now: float) -> None:
        elapsed = now - self._start
        percent = 100.0 * self.done / self.total if self.total else 100.0
        line = f"{self.what}: {self.done}/{self.total} frames ({percent:.0f} %), {elapsed:.0f} s"
        rate = (self.done - self._start_done) / elapsed if elapsed > 0 else 0.0
        if 0 < self.done < self.total and rate > 0:
            line += f", about {(self.total - self.done) / rate:.0f} s left"
        self.stream.write(line + "\n")
        self.stream.flush()
        self._last, self._shown = now, self.done


def _delay_from_environment(default: float) -> float:
    """``$JELLYSIM_PROGRESS_DELAY`` as seconds (0 shows every bar at once), else ``default``;
    a value that is not a number, or is negative, is ignored."""
    try:
        value = float(os.environ[DELAY_ENV])
    except (KeyError, ValueError):
        return default
    return value if value >= 0 else default
