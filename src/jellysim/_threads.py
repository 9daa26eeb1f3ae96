"""Numba's threading layer, chosen by jellysim (docs/decisions.md, "Threading layer").

Numba tries TBB first when ``libtbb12`` is installed (Blender, OpenCV, OpenVDB, Embree and
OpenImageIO bring it on Debian). On a machine whose cores other work shares, jellysim's parallel
kernels then ran a thousand times slower, and the interpreter hung in TBB's finalization at exit
(Numba issue #10556). jellysim puts OpenMP first, then the workqueue, TBB last; a user who sets
``NUMBA_THREADING_LAYER`` (a layer by name) or ``NUMBA_THREADING_LAYER_PRIORITY`` keeps the choice.
Importing any part of jellysim imports the package first, and the package imports this module
first.
"""

from __future__ import annotations

import os
import sys

PRIORITY = ("omp", "workqueue", "tbb")
PRIORITY_VARIABLE = "NUMBA_THREADING_LAYER_PRIORITY"


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


prefer_safe_threading_layer()
