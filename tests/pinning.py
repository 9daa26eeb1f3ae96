"""One floating-point path on every x86-64 host, for the bit-for-bit gates.

The regression gates (tests/regression, ``test_loops.py``) compare runs with stored results bit
for bit. Three things a host picks change the last bits of a run: the code Numba generates for the
host's processor (its instructions; since 2026-11-28 no kernel lets ``fastmath`` reassociate
its sums, which made the vector width reorder them), NumPy's
runtime SIMD dispatch (AVX-512 versions of its ufuncs and sorts) and OpenBLAS's kernel and thread
count. Imported by ``conftest.py`` before NumPy, SciPy or Numba load, this module pins all of them
to the x86-64-v3 level (AVX2 and FMA, which every x86-64 server of the last decade has), so the
stored results hold on Intel and AMD hosts alike (docs/decisions.md, "One floating-point path for
the tests"). Child processes inherit the pin. A variable already set is left as it is; a host
without x86-64-v3 is not pinned, and the bit-for-bit tests say so and skip (:data:`PINNED`).
"""

from __future__ import annotations

import os
import platform
from pathlib import Path

# The x86-64-v3 level's CPU flags as /proc/cpuinfo names them.
_V3_FLAGS = {"avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "movbe", "abm", "xsave"}


def _numpy_at_least(major: int, minor: int) -> bool:
    """Whether the installed NumPy is at least ``major.minor``, read from its metadata (NumPy
    itself must not load yet)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        parts = version("numpy").split(".")
        return (int(parts[0]), int(parts[1])) >= (major, minor)
    except (PackageNotFoundError, ValueError, IndexError):
        return False


PIN = {
    "NUMBA_CPU_NAME": "x86-64-v3",
    "NUMBA_CPU_FEATURES": "",  # the level's own features, not the host's
    "OPENBLAS_CORETYPE": "Haswell",
    "OPENBLAS_NUM_THREADS": "1",
}
# NumPy 2.3 and later dispatch to X86_V3, X86_V4 (AVX-512) and two AVX-512 extensions; turning
# off a name it does not dispatch to is an ImportWarning (an error under -W error). Earlier
# versions name each AVX-512 set and differ in which they dispatch to: not pinned there.
if _numpy_at_least(2, 3):
    PIN["NPY_DISABLE_CPU_FEATURES"] = "X86_V4 AVX512_ICL AVX512_SPR"


def _host_has_v3() -> bool:
    if platform.system() != "Linux" or platform.machine() != "x86_64":
        return False
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return False
    flags = next(
        (line.split(":", 1)[1].split() for line in text.splitlines() if line.startswith("flags")),
        [],
    )
    return _V3_FLAGS <= set(flags)


if _host_has_v3():
    for _name, _value in PIN.items():
        os.environ.setdefault(_name, _value)
# Whether this session runs on the pinned path (the stored results' own).
PINNED = _numpy_at_least(2, 3) and all(os.environ.get(k) == v for k, v in PIN.items())

NOT_PINNED = (
    "the stored results hold on the x86-64-v3 path that tests/pinning.py pins; this session is not "
    "on it (another processor, NumPy before 2.3, or one of its variables set otherwise)"
)
