"""Numba's threading layer, chosen by jellysim (docs/decisions.md, "Threading layer").

Numba tries TBB first when ``libtbb12`` is installed (Blender, OpenCV, OpenVDB, Embree and
OpenImageIO bring it on Debian). On a machine whose cores other work shares, jellysim's parallel
kernels then ran a thousand times slower, and the interpreter hung in TBB's finalization at exit
(Numba issue #10556). jellysim puts OpenMP first, then the workqueue, TBB last; a user who sets
``NUMBA_THREADING_LAYER`` (a layer by name) or ``NUMBA_THREADING_LAYER_PRIORITY`` keeps the choice.

GNU OpenMP's threads spin between parallel regions by default. When other processes share the
cores they spin on borrowed time: on 16 cores with 16 busy processes the 3-D tank ran 1.07 steps/s
against 3.00 with the passive wait policy (and 1.6x slower on 2 cores), while on idle cores passive
costs 2 % (2 cores) to 14 % (16 cores). jellysim therefore sets ``OMP_WAIT_POLICY=passive`` unless
the user sets ``OMP_WAIT_POLICY`` or ``GOMP_SPINCOUNT``. libgomp reads it when it is loaded, which
is at Numba's first parallel kernel, so it holds unless another library loaded libgomp before.
Importing any part of jellysim imports the package first, and the package imports this module
first.
"""

from __future__ import annotations

import os
import sys

PRIORITY = ("omp", "workqueue", "tbb")
PRIORITY_VARIABLE = "NUMBA_THREADING_LAYER_PRIORITY"
WAIT_POLICY = "passive"
WAIT_VARIABLES = ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")  # either one is the user's choice


def prefer_safe_threading_layer() -> None:
    """Put OpenMP and the workqueue before TBB, unless the user chose. Set in the environment
    (Numba re-reads its configuration from it, and child processes inherit it) and in Numba's
    configuration if Numba is already imported; it takes effect unless a parallel kernel has
    already run in this process."""
    if PRIORITY_VARIABLE in os.environ:
        return
    os.environ[PRIORITY_VARIABLE] = " ".join(PRIORITY)
    config = sys.modules.get("numba.core.config")
    if config is not None:
        config.THREADING_LAYER_PRIORITY = list(PRIORITY)  # type: ignore[attr-defined]


def prefer_passive_openmp_threads() -> None:
    """Let OpenMP's idle threads sleep instead of spinning, unless the user chose (in the
    environment, where libgomp reads it when loaded; child processes inherit it)."""
    if any(name in os.environ for name in WAIT_VARIABLES):
        return
    os.environ[WAIT_VARIABLES[0]] = WAIT_POLICY


prefer_safe_threading_layer()
prefer_passive_openmp_threads()
