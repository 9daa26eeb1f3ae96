"""The pressure solvers by name: each solves the PPE ``A p = b``, Eq. (F11)-(F12a) of
docs/theory/fluid.md, behind the :class:`PressureSolver` Protocol; a scene names one
(``fluid.solver``) and :func:`solve` looks it up in :data:`PRESSURE_SOLVERS`.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol

import numpy as np

from jellysim.errors import SimulationUnstable
from jellysim.fluid.deflation import deflated_cg
from jellysim.fluid.linalg import (
    Identity,
    Matrix,
    compact_factor,
    conjugate_gradient,
    incomplete_cholesky,
)

IC_SHIFTS = (1e-3, 1e-2, 1e-1, 1.0)  # diagonal shifts tried in turn when IC(0) breaks down


class FluidDiverged(SimulationUnstable):
    """The pressure solve did not converge, or the state stopped being finite (exit status 3).

    ``time`` is the solver's own clock (the sum of the steps taken), in s.
    """

    def __init__(self, message: str, *, time: float, iterations: int, residual: float) -> None:
        super().__init__(message, time=time)
        self.iterations = iterations
        self.residual = residual


class CoarseSpace(NamedTuple):
    """Where the rows of a PPE are, for the deflated solver's aggregates: ``position`` (n, D) m
    in row order, the aggregates' lattice ``origin`` (D,) m and cell ``size`` m."""

    position: np.ndarray
    origin: np.ndarray
    size: float


class PressureSolver(Protocol):
    """A pressure solver of the registry :data:`PRESSURE_SOLVERS`: solves ``A p = b`` in place
    in ``solution`` (initial guess in, answer out) to the relative residual ``tolerance``, and
    returns (iterations, relative residual, IC shift used, 0 when none)."""

    def __call__(
        self,
        matrix: Matrix,
        rhs: np.ndarray,
        solution: np.ndarray,
        tolerance: float,
        max_iterations: int,
        coarse: CoarseSpace | None,
    ) -> tuple[int, float, float]: ...


def _conjugate_gradient(
    matrix: Matrix,
    rhs: np.ndarray,
    solution: np.ndarray,
    tolerance: float,
    max_iterations: int,
    coarse: CoarseSpace | None,
) -> tuple[int, float, float]:
    """Plain CG (no preconditioner), for comparison."""
    iterations, residual = conjugate_gradient(
        matrix, Identity(rhs.shape[0]), rhs, solution, tolerance, max_iterations
    )
    return iterations, residual, 0.0


def _incomplete_cholesky_cg(
    matrix: Matrix,
    rhs: np.ndarray,
    solution: np.ndarray,
    tolerance: float,
    max_iterations: int,
    coarse: CoarseSpace | None,
) -> tuple[int, float, float]:
    """ICCG: IC(0) is tried unshifted, then with the diagonal shifts ``IC_SHIFTS`` in turn if a
    pivot is not positive."""
    factor = np.zeros(matrix.data.shape)  # L in double, whatever A's entries are stored in
    for shift in (0.0, *IC_SHIFTS):
        if incomplete_cholesky(matrix, shift, factor):
            break
    else:
        raise FluidDiverged(
            "IC(0) broke down even with the largest diagonal shift",
            time=math.nan,
            iterations=0,
            residual=math.inf,
        )
    compact = compact_factor(matrix, factor)
    iterations, residual = conjugate_gradient(
        matrix, compact, rhs, solution, tolerance, max_iterations
    )
    return iterations, residual, shift


def _deflated_cg(
    matrix: Matrix,
    rhs: np.ndarray,
    solution: np.ndarray,
    tolerance: float,
    max_iterations: int,
    coarse: CoarseSpace | None,
) -> tuple[int, float, float]:
    """CG with Jacobi and a coarse problem on aggregates of particles (``coarse`` required;
    :mod:`jellysim.fluid.deflation`)."""
    if coarse is None:
        raise ValueError("the deflated solver needs the rows' positions (coarse)")
    try:
        iterations, residual = deflated_cg(
            matrix, *coarse, rhs, solution, tolerance, max_iterations
        )
    except RuntimeError as error:  # SuperLU: a singular coarse matrix (A not definite)
        raise FluidDiverged(
            f"the deflated solver's coarse problem could not be factored ({error})",
            time=math.nan,
            iterations=0,
            residual=math.inf,
        ) from None
    return iterations, residual, 0.0


# The pressure solvers by the name a scene gives (fluid.solver); config.schema lists the same
# names (a unit test holds the two together).
PRESSURE_SOLVERS: dict[str, PressureSolver] = {
    "iccg": _incomplete_cholesky_cg,
    "cg": _conjugate_gradient,
    "deflated": _deflated_cg,
}


def solve(
    matrix: Matrix,
    rhs: np.ndarray,
    solution: np.ndarray,
    method: str = "iccg",
    tolerance: float = 1e-8,
    max_iterations: int = 2000,
    coarse: CoarseSpace | None = None,
) -> tuple[int, float, float]:
    """Solve the PPE in place in ``solution`` (initial guess in, answer out) by the solver of
    :data:`PRESSURE_SOLVERS` named ``method`` ("iccg", "cg" or "deflated", which needs
    ``coarse``). Returns (iterations, relative residual, IC shift used)."""
    if method not in PRESSURE_SOLVERS:
        raise ValueError(f"solver = {method!r}; allowed: {', '.join(PRESSURE_SOLVERS)}")
    return PRESSURE_SOLVERS[method](matrix, rhs, solution, tolerance, max_iterations, coarse)
