"""The soft bell's springs and circular muscle on the GPU (``fluid.device = "cuda"``): Eq. B8-B9
and their linearised backward Euler in CUDA kernels beside the water's
:class:`jellysim.fluid.gpu.GPUSolver`, so that a step of the bell in its water moves no particle
array between the host and the GPU (issue 28).

The bell's particles are rows ``rows`` of the solver's state (the coupling puts them together,
:mod:`jellysim.coupling.bell_in_fluid`). Each MPS step:

- ``spring_terms`` (a thread a spring): the muscle's rest length and stiffness at the activation
  ``a`` (read on the host from the pulse waveform: one number), the spring's tension ``f_e``
  (Eq. B8) and, for the implicit integration, its direction ``n`` and the two stiffnesses of its
  block ``K_e = along n n^T + across (I - n n^T)`` (:func:`jellysim.bell.springs.
  implicit_velocity_change`, whose compressed springs lose their negative transverse part).
- ``explicit``: the force ``F_i = sum s f_e`` gathered through each particle's adjacency (as
  :func:`jellysim.bell.springs.gather_forces`), written as the force density ``F / l0^3`` into
  the explicit stage's external-force array on the GPU.
- ``implicit`` (``spring_integration = "implicit"``): each particle writes its three rows of
  ``(m I - dt^2 K) dv = dt (F + dt K v)`` into a matrix of fixed-width rows (slot-major, as the
  pressure's), with the guess ``dv = dt F / m``; the pressure's cooperative CG
  (:mod:`jellysim.fluid.gpu`, Jacobi-preconditioned, to ``IMPLICIT_TOLERANCE`` of |b| as on the
  CPU) solves it in one launch, and ``from_velocity_change`` writes ``m dv / dt / l0^3``.

The tentacles' drag reaction (flow.two_way) is uploaded once a frame and added to every step's
density as on the CPU. Each particle sums its own springs in the adjacency's order (no
floating-point atomics): two runs on one GPU give the same bits. The explicit force is the CPU's
operations in the CPU's order (bit for bit in the simulator; a GPU may contract to FMAs); the
implicit solve is another preconditioner's CG, so it agrees with the CPU's to the tolerance.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from jellysim.bell.soft import IMPLICIT_TOLERANCE, SoftBell
from jellysim.errors import SimulationUnstable
from jellysim.fluid import gpu
from jellysim.fluid.gpu import (  # cuda a module global: the simulator swaps it
    BLOCK,
    _grid,
    cooperative_blocks,
    cuda,
)

# The implicit solve's iterations at most (the CPU's too).
MAX_ITERATIONS = 1000

_KERNELS: dict[str, Any] | None = None


def _kernels() -> dict[str, Any]:
    """The springs' CUDA kernels by name (:mod:`jellysim.bell.gpu_spring_kernels`, imported on
    first use; compiled at a first launch or loaded from Numba's cache)."""
    global _KERNELS
    if _KERNELS is None:
        from jellysim.bell import gpu_spring_kernels

        _KERNELS = gpu_spring_kernels.KERNELS
    return _KERNELS


class GPUSprings:
    """The springs and muscle of ``body`` (its particles the rows ``rows`` of ``solver``) on the
    GPU: :meth:`force_density` gives each step's external force density as a device array,
    the soft bell's :meth:`SoftBell.step_force` divided by l0^3 (``cell_volume``, m3)."""

    def __init__(self, body: SoftBell, solver: Any, rows: slice, cell_volume: float) -> None:
        self.k = _kernels()
        self.body = body
        self.solver = solver
        self.base = rows.start
        self.particles = rows.stop - rows.start
        self.implicit = body.integration == "implicit"
        self.volume = cell_volume
        s = body.springs
        n_springs = len(s.pairs)
        share = np.zeros(n_springs)
        share[s.muscle] = 1.0 if body.muscle_weight is None else body.muscle_weight
        d, da = cuda.to_device, cuda.device_array
        self._pairs = d(np.ascontiguousarray(s.pairs))
        self._rest = d(s.rest_length)
        self._share = d(share)
        self._start = d(s.start)
        self._edges = d(s.edges)
        self._signs = d(s.signs)
        self._tension = da((max(n_springs, 1), 3))
        self._normal = da((max(n_springs, 1), 3))
        self._along = da(max(n_springs, 1))
        self._across = da(max(n_springs, 1))
        n = solver.n
        self._force = d(np.zeros((n, 3)))
        self._reaction = da((1, 3))
        self._with_reaction = False
        if self.implicit:
            rows3 = 3 * self.particles
            degree = int(np.diff(s.start).max(initial=0))
            width = 2 + 3 * degree
            self._index = d(np.zeros((width, rows3), dtype=np.int32))
            self._count = da(rows3, dtype=np.int32)
            self._coefficient = d(np.zeros((width, rows3)))
            self._diagonal, self._inverse_diagonal = da(rows3), da(rows3)
            self._b, self._x = da(rows3), da(rows3)
            self._r, self._z, self._d, self._q = da(rows3), da(rows3), da(rows3), da(rows3)
            self._partial = da((2, _grid(rows3), 3))
            self._out = da(4)
            self._blocks = 0

    def set_reaction(self, reaction: np.ndarray | None) -> None:
        """The tentacles' drag reaction (N, 3) N/m3 over the next frame (flow.two_way), or None:
        uploaded once, added to every step's density (Eq. S2)."""
        if reaction is None:
            if self._with_reaction:  # the water's rows back to no force
                self._force.copy_to_device(np.zeros(self._force.shape))
            self._with_reaction = False
            return
        values = np.ascontiguousarray(reaction, dtype=np.float64)
        if self._reaction.shape != values.shape:
            self._reaction = cuda.to_device(values)
        else:
            self._reaction.copy_to_device(values)
        self._force.copy_to_device(values)  # the water's rows; the bell's are rewritten a step
        self._with_reaction = True

    def force_density(self, time: float, dt: float) -> Any:
        """The external force density (N, 3) N/m3 on the GPU for an MPS step of ``dt`` (s) from
        ``time``: the springs' force now (explicit) or over the step by backward Euler with the
        muscle at ``time + dt`` (implicit), as :meth:`SoftBell.step_force`. Raises
        SimulationUnstable where the implicit solve does not converge, as the CPU does."""
        body, k = self.body, self.k
        at = time + dt if self.implicit else time
        a = body.activation(at)
        springs = self._pairs.shape[0]
        k["spring_terms"][_grid(springs), BLOCK](
            self.solver.device_position, self.base, self._pairs, self._rest, self._share,
            body.stiffness, body.muscle_ratio * a, (body.muscle_stiffening - 1.0) * a,
            self._tension, self._normal, self._along, self._across,
        )  # fmt: skip
        grid = _grid(self.particles)
        if not self.implicit:
            k["explicit"][grid, BLOCK](
                self._tension, self._start, self._edges, self._signs, self.volume,
                self.base, self._reaction, self._with_reaction, self._force,
            )  # fmt: skip
            return self._force
        k["implicit"][grid, BLOCK](
            self.solver.device_velocity, self.base, self._pairs, self._start, self._edges,
            self._signs, self._tension, self._normal, self._along, self._across, body.mass, dt,
            self._index, self._count, self._coefficient, self._diagonal, self._inverse_diagonal,
            self._b, self._x,
        )  # fmt: skip
        iterations, residual = self._solve()
        if not residual <= IMPLICIT_TOLERANCE:
            raise SimulationUnstable(
                f"the implicit spring solve stopped at relative residual {residual:.3g} after "
                f"{iterations} iterations at t = {time:.6g} s",
                time=time,
            )
        k["from_velocity_change"][grid, BLOCK](
            self._x, body.mass, dt, self.volume, self.base, self._reaction,
            self._with_reaction, self._force,
        )  # fmt: skip
        return self._force

    def _solve(self) -> tuple[int, float]:
        """The pressure's cooperative CG on the springs' rows, from the guess in ``_x``."""
        args = (
            self._index, self._count, self._coefficient, self._diagonal, self._inverse_diagonal,
            self._b, self._x, self._r, self._z, self._d, self._q, self._partial,
            IMPLICIT_TOLERANCE**2, MAX_ITERATIONS, self._out, *gpu.no_coarse_space(),
        )  # fmt: skip
        kernel = gpu._kernels()["conjugate_gradient"]
        if self._blocks == 0:
            self._blocks = cooperative_blocks(kernel, args, _grid(3 * self.particles))
        kernel[self._blocks, BLOCK](*args)
        iterations, rr, bb, _ = self._out.copy_to_host()
        residual = 0.0 if bb == 0.0 else math.sqrt(rr / bb)
        return int(iterations), residual


__all__ = ["GPUSprings"]
