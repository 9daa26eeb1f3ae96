"""One straight chain hanging from a root held still at the origin, pointing down, in still
water (importable: pytest's pythonpath holds tests/). Shared by the kernel, cantilever and
terminal-velocity tests."""

from __future__ import annotations

import numpy as np

from jellysim.tentacle.contact import no_obstacle
from jellysim.tentacle.kernels import ChainModel, Medium, advance_frame

DOWN = np.array([0.0, 0.0, -1.0])


def hang(
    x: np.ndarray, v: np.ndarray, model: ChainModel, medium: Medium, steps: int, dt: float
) -> np.ndarray:
    """Advance the chain ``x``, ``v`` (1, P, 3) in place by ``steps`` substeps of ``dt`` with
    its root fixed with direction DOWN (a clamp where the model clamps), no curl and no flow;
    returns the (1, 3) diagnostics."""
    zeros = np.zeros((steps, 1, 3))
    diagnostics = np.zeros((1, 3))
    advance_frame(
        x,
        v,
        zeros,
        zeros,
        zeros + DOWN,
        zeros,
        np.zeros_like(x),
        zeros[:, :, None],  # still water, one velocity per chain
        model,
        medium,
        dt,
        diagnostics,
        np.zeros((1, 0, 3)),  # no drag impulse recorded
        no_obstacle(),
    )
    return diagnostics
