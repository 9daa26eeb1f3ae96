"""``jellysim`` as a user runs it, with one fault injected (the fault-injection suite's driver).

    python runner.py FAULT -- ARGS...     (ARGS: what follows ``jellysim`` on the command line)

FAULT is one of:

- ``none``: no fault.
- ``pause-in-write:K``: in the K-th batch of frames the result store writes (K >= 1), stop after its
  first dataset is written and before ``time`` is, print ``PAUSED`` on stderr and wait to be
  killed: the moment "during a frame's write".
- ``pause-in-flush:K``: the same, once every dataset of the K-th batch is written but before
  HDF5 flushes them to disk.
- ``pause-in-checkpoint:K``: while the K-th checkpoint is being written (its temporary file
  holds the arrays, not yet renamed).
- ``pause-after-replace:NAME``: just after the first ``os.replace`` onto a file called NAME (the
  moment a new ``result.h5`` has taken its name, before its XDMF sidecar is written).
- ``enospc-at:K``: the K-th HDF5 flush fails with ENOSPC (a full disk, where the test cannot
  mount a small file system).
- ``free-space-lies``: the file system reports 1 TiB free, so the writer's own check passes and
  the disk's real refusal (ENOSPC from HDF5) is what stops the run.

The injection wraps the library functions the writer calls (h5py, numpy, shutil) in this
process only; jellysim's code is not changed.
"""

from __future__ import annotations

import errno
import os
import shutil
import sys
import time
from collections.abc import Callable
from typing import Any

import h5py
import numpy as np


def _pause(what: str) -> None:
    print(f"PAUSED {what}", file=sys.stderr, flush=True)
    while True:
        time.sleep(60)


def _counting(original: Callable[..., Any], before: Callable[[int, tuple[Any, ...]], None]) -> Any:
    calls = [0]

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        calls[0] += 1
        before(calls[0], args)
        return original(*args, **kwargs)

    return wrapper


def install(fault: str) -> None:
    name, _, argument = fault.partition(":")
    k = int(argument) if argument.isdigit() else 0
    if name == "none":
        return
    if name in ("pause-in-write", "pause-in-flush", "pause-in-checkpoint", "enospc-at"):
        assert k >= 1, fault
    if name == "pause-in-write":
        from jellysim.io import result

        batches = [0]
        original_flush = result.ResultWriter.flush

        def flush(self: Any) -> None:
            batches[0] += bool(self._buffer["time"])
            if batches[0] == k and self._buffer["time"]:
                first = sorted(self._datasets)[0]
                dataset = self._datasets[first]
                rows = self.frames + len(self._buffer[first])
                dataset.resize(rows, axis=0)
                dataset[self.frames :] = np.stack(self._buffer[first])
                _pause(f"in batch {k} after writing {first}")
            original_flush(self)

        result.ResultWriter.flush = flush  # type: ignore[method-assign]
    elif name == "pause-in-flush":

        def before(call: int, _args: tuple[Any, ...]) -> None:
            if call == k + 1:  # the first flush completes the new file
                _pause(f"before HDF5 flush {call}")

        h5py.File.flush = _counting(h5py.File.flush, before)  # type: ignore[method-assign]
    elif name == "pause-in-checkpoint":
        original_savez = np.savez

        def savez(handle: Any, *args: Any, **kwargs: Any) -> None:
            original_savez(handle, *args, **kwargs)
            savez.calls += 1  # type: ignore[attr-defined]
            if savez.calls == k:  # type: ignore[attr-defined]
                handle.flush()
                _pause(f"writing checkpoint {k}")

        savez.calls = 0  # type: ignore[attr-defined]
        np.savez = savez
    elif name == "pause-after-replace":
        original_replace = os.replace

        def replace(source: Any, target: Any, **kwargs: Any) -> None:
            original_replace(source, target, **kwargs)
            if os.path.basename(os.fspath(target)) == argument:
                _pause(f"after {argument} took its name")

        os.replace = replace
    elif name == "enospc-at":

        def fail(call: int, _args: tuple[Any, ...]) -> None:
            if call == k + 1:
                raise OSError(errno.ENOSPC, "No space left on device (injected)")

        h5py.File.flush = _counting(h5py.File.flush, fail)  # type: ignore[method-assign]
    elif name == "free-space-lies":
        usage = shutil.disk_usage

        def lying(path: Any) -> Any:
            real = usage(path)
            return type(real)(real.total, real.used, 2**40)

        shutil.disk_usage = lying  # type: ignore[assignment]
    else:
        raise SystemExit(f"runner: unknown fault {fault!r}")


def main() -> int:
    fault, separator, *argv = sys.argv[1:]
    assert separator == "--", sys.argv
    install(fault)
    from jellysim.cli.main import main as jellysim

    return jellysim(argv)


if __name__ == "__main__":
    sys.exit(main())
