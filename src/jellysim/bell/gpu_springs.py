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
    """The springs' CUDA kernels, compiled on first use."""
    global _KERNELS
    if _KERNELS is None:
        _KERNELS = _build_kernels()
    return _KERNELS


def _build_kernels() -> dict[str, Any]:  # noqa: C901 - one closure per kernel
    @cuda.jit
    def spring_terms(
        position, base, pairs, rest_length, share, stiffness, ratio_a, stiffening_a,
        tension, normal, along, across,
    ):  # fmt: skip
        """Per spring e = (a, b) at the activation's ``ratio_a`` = muscle_ratio a and
        ``stiffening_a`` = (muscle_stiffening - 1) a: L_e = L0 (1 - ratio_a share_e),
        k_e = k (1 + stiffening_a share_e) (Eq. B9; share 0 for a passive spring);
        ``tension`` f_e = k_e (|d| - L_e) d / |d| with d = r_b - r_a (Eq. B8), ``normal`` n,
        ``along`` k_e and ``across`` k_e max(1 - L_e / |d|, 0)."""
        e = cuda.grid(1)
        if e >= pairs.shape[0]:
            return
        a = base + pairs[e, 0]
        b = base + pairs[e, 1]
        length_rest = rest_length[e] * (1.0 - ratio_a * share[e])
        k = stiffness * (1.0 + stiffening_a * share[e])
        d0 = position[b, 0] - position[a, 0]
        d1 = position[b, 1] - position[a, 1]
        d2 = position[b, 2] - position[a, 2]
        length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        scale = 0.0
        n0 = d0
        n1 = d1
        n2 = d2
        stretch = 0.0
        if length > 0.0:
            scale = k * (length - length_rest) / length
            n0 = d0 / length
            n1 = d1 / length
            n2 = d2 / length
            stretch = max(1.0 - length_rest / length, 0.0)
        tension[e, 0] = scale * d0
        tension[e, 1] = scale * d1
        tension[e, 2] = scale * d2
        normal[e, 0] = n0
        normal[e, 1] = n1
        normal[e, 2] = n2
        along[e] = k if length > 0.0 else 0.0
        across[e] = k * stretch

    @cuda.jit
    def explicit(tension, start, edges, signs, volume, base, reaction, with_reaction, out):
        """``out[base + i]`` = F_i / l0^3 (+ the reaction there), F_i the sum of ``sign * f_e``
        over particle i's springs in adjacency order (:func:`gather_forces`)."""
        i = cuda.grid(1)
        if i >= start.shape[0] - 1:
            return
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        for m in range(start[i], start[i + 1]):
            e = edges[m]
            s = signs[m]
            f0 += s * tension[e, 0]
            f1 += s * tension[e, 1]
            f2 += s * tension[e, 2]
        row = base + i
        if with_reaction:
            out[row, 0] = reaction[row, 0] + f0 / volume
            out[row, 1] = reaction[row, 1] + f1 / volume
            out[row, 2] = reaction[row, 2] + f2 / volume
        else:
            out[row, 0] = f0 / volume
            out[row, 1] = f1 / volume
            out[row, 2] = f2 / volume

    @cuda.jit
    def implicit(
        velocity, base, pairs, start, edges, signs, tension, normal, along, across, mass, dt,
        index, count, coefficient, diagonal, inverse_diagonal, rhs, guess,
    ):  # fmt: skip
        """Particle i's three rows 3i + k of ``(m I - dt^2 K) dv = dt (F + dt K v)``: K's
        block for spring e to the other end o is K_io = K_e and K_ii = -sum K_e, so the row
        holds ``-dt^2 K_e`` at o's three columns and ``m I + dt^2 sum K_e`` on i's; stored as
        the pressure's rows, ``A x = diagonal x_i - sum coefficient x_index``. ``rhs`` the
        right side, ``guess`` dt F / m."""
        i = cuda.grid(1)
        if i >= start.shape[0] - 1:
            return
        h2 = dt * dt
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        kv0 = 0.0
        kv1 = 0.0
        kv2 = 0.0
        s00 = 0.0
        s01 = 0.0
        s02 = 0.0
        s11 = 0.0
        s12 = 0.0
        s22 = 0.0
        slot = 2
        for m in range(start[i], start[i + 1]):
            e = edges[m]
            s = signs[m]
            f0 += s * tension[e, 0]
            f1 += s * tension[e, 1]
            f2 += s * tension[e, 2]
            a = base + pairs[e, 0]
            b = base + pairs[e, 1]
            other = pairs[e, 1] if s > 0.0 else pairs[e, 0]
            n0 = normal[e, 0]
            n1 = normal[e, 1]
            n2 = normal[e, 2]
            p = along[e]
            q = across[e]
            # K_e (v_b - v_a), the force on a; on b it is minus that
            v0 = velocity[b, 0] - velocity[a, 0]
            v1 = velocity[b, 1] - velocity[a, 1]
            v2 = velocity[b, 2] - velocity[a, 2]
            dot = n0 * v0 + n1 * v1 + n2 * v2
            kv0 += s * (p * n0 * dot + q * (v0 - n0 * dot))
            kv1 += s * (p * n1 * dot + q * (v1 - n1 * dot))
            kv2 += s * (p * n2 * dot + q * (v2 - n2 * dot))
            # K_e = (p - q) n n^T + q I
            c = p - q
            b00 = c * n0 * n0 + q
            b01 = c * n0 * n1
            b02 = c * n0 * n2
            b11 = c * n1 * n1 + q
            b12 = c * n1 * n2
            b22 = c * n2 * n2 + q
            s00 += b00
            s01 += b01
            s02 += b02
            s11 += b11
            s12 += b12
            s22 += b22
            for k in range(3):
                row = 3 * i + k
                index[slot, row] = 3 * other
                index[slot + 1, row] = 3 * other + 1
                index[slot + 2, row] = 3 * other + 2
            coefficient[slot, 3 * i] = h2 * b00
            coefficient[slot + 1, 3 * i] = h2 * b01
            coefficient[slot + 2, 3 * i] = h2 * b02
            coefficient[slot, 3 * i + 1] = h2 * b01
            coefficient[slot + 1, 3 * i + 1] = h2 * b11
            coefficient[slot + 2, 3 * i + 1] = h2 * b12
            coefficient[slot, 3 * i + 2] = h2 * b02
            coefficient[slot + 1, 3 * i + 2] = h2 * b12
            coefficient[slot + 2, 3 * i + 2] = h2 * b22
            slot += 3
        # i's own block: the two other components of each row in slots 0 and 1
        r0 = 3 * i
        r1 = r0 + 1
        r2 = r0 + 2
        index[0, r0] = r1
        index[1, r0] = r2
        coefficient[0, r0] = -h2 * s01
        coefficient[1, r0] = -h2 * s02
        index[0, r1] = r0
        index[1, r1] = r2
        coefficient[0, r1] = -h2 * s01
        coefficient[1, r1] = -h2 * s12
        index[0, r2] = r0
        index[1, r2] = r1
        coefficient[0, r2] = -h2 * s02
        coefficient[1, r2] = -h2 * s12
        diagonal[r0] = mass + h2 * s00
        diagonal[r1] = mass + h2 * s11
        diagonal[r2] = mass + h2 * s22
        for r in range(r0, r0 + 3):
            count[r] = slot
            inverse_diagonal[r] = 1.0 / diagonal[r]
        rhs[r0] = dt * (f0 + dt * kv0)
        rhs[r1] = dt * (f1 + dt * kv1)
        rhs[r2] = dt * (f2 + dt * kv2)
        guess[r0] = dt * f0 / mass
        guess[r1] = dt * f1 / mass
        guess[r2] = dt * f2 / mass

    @cuda.jit
    def from_velocity_change(change, mass, dt, volume, base, reaction, with_reaction, out):
        """``out[base + i]`` = (m dv_i / dt) / l0^3 (+ the reaction there)."""
        i = cuda.grid(1)
        if i >= change.shape[0] // 3:
            return
        row = base + i
        for k in range(3):
            density = mass * change[3 * i + k] / dt / volume
            if with_reaction:
                density = reaction[row, k] + density
            out[row, k] = density

    return {name: value for name, value in locals().items() if callable(value)}


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
            self._out = da(3)
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
        iterations, rr, bb = self._out.copy_to_host()
        residual = 0.0 if bb == 0.0 else math.sqrt(rr / bb)
        return int(iterations), residual


__all__ = ["GPUSprings"]
