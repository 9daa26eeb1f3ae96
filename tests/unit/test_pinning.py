"""The tests' one floating-point path (tests/pinning.py) is in effect where it is claimed: the
bit-for-bit gates rely on NumPy, Numba and OpenBLAS having read the pinned variables, which they
do only when nothing loaded them before ``conftest.py`` imported ``pinning``."""

from __future__ import annotations

import pytest
from pinning import NOT_PINNED, PIN, PINNED


@pytest.mark.skipif(not PINNED, reason=NOT_PINNED)
def test_numba_and_numpy_run_on_the_pinned_path() -> None:
    import numba
    from numpy._core._multiarray_umath import __cpu_features__  # type: ignore[attr-defined]

    assert numba.config.CPU_NAME == "x86-64-v3"  # type: ignore[attr-defined]
    assert numba.config.CPU_FEATURES == ""  # type: ignore[attr-defined]  # not the host's
    for feature in PIN["NPY_DISABLE_CPU_FEATURES"].split():
        assert not __cpu_features__.get(feature, False), feature
    assert __cpu_features__["X86_V3"]  # the level itself stays on
