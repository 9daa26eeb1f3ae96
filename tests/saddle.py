"""A saddle-point system as the tentacle kernel assembles it, in the banded solve's padded storage
(importable: pytest's pythonpath holds tests/). Shared by the scalar and the lanes' solve tests."""

from __future__ import annotations

import numpy as np

from jellysim.tentacle.kernels import KKT_HALF_BANDWIDTH, KKT_PADDING


def saddle_system(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` unknowns, three a particle then its multiplier (an SPD block over the particles'
    unknowns, each multiplier coupled to the unknowns before it within the band): the dense
    matrix (n, n), its lower band in padded storage (n + 2 KKT_PADDING, KKT_HALF_BANDWIDTH + 1)
    and a right-hand side in padded storage (n + 2 KKT_PADDING,)."""
    b = KKT_HALF_BANDWIDTH
    a = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - b), i + 1):
            if i % 4 != 3 and j % 4 != 3:
                a[i, j] = rng.uniform(-0.2, 0.2) if i != j else rng.uniform(4, 5)
            elif i % 4 == 3 and j != i and j > i - 8:
                a[i, j] = rng.uniform(-1, 1)
    a = np.tril(a) + np.tril(a, -1).T
    band = np.zeros((n + 2 * KKT_PADDING, b + 1))
    for i in range(n):
        for s in range(b + 1):
            if i - s >= 0:
                band[KKT_PADDING + i, s] = a[i, i - s]
    rhs = np.zeros(n + 2 * KKT_PADDING)
    rhs[KKT_PADDING : KKT_PADDING + n] = rng.normal(size=n)
    return a, band, rhs
