"""The banded LDL^T solve of several chains at once, one chain in each lane of a vector register
(docs/theory/tentacle.md, Eq. T7; docs/decisions.md, "Chains in the lanes of a vector").

:func:`band_ldlt_solve_lanes` performs, lane by lane, exactly the arithmetic of the scalar
:func:`jellysim.tentacle.kernels._band_ldlt_solve` (the same products, fused multiply-adds and
divisions in the same order), on ``LANES`` independent systems whose entries are interleaved:
``band[r, s, l]`` is entry ``band[r, s]`` of lane l's system. Numba does not vectorise such code
itself (its loop vectoriser runs after small fixed loops are unrolled, and its SLP vectoriser is
off), so the solve is generated as LLVM vector instructions by a Numba intrinsic.
"""

from __future__ import annotations

from typing import Any

from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

LANES = 8  # systems solved together: 8 doubles fill an AVX-512 register, two AVX2 ones
BAND = 8  # half-bandwidth, equal to kernels.KKT_HALF_BANDWIDTH (checked there)


def _lane_arrays_ok(band: Any, inverse_pivots: Any, rhs: Any) -> bool:
    """The intrinsic takes C-contiguous float64 arrays: band (N, BAND + 1, LANES), inverse
    pivots and right-hand sides (N, LANES)."""
    return (
        isinstance(band, types.Array)
        and band.ndim == 3
        and band.layout == "C"
        and band.dtype == types.float64
        and all(
            isinstance(a, types.Array)
            and a.ndim == 2
            and a.layout == "C"
            and a.dtype == types.float64
            for a in (inverse_pivots, rhs)
        )
    )


@intrinsic
def _band_ldlt_solve_lanes(typingctx: Any, band: Any, inverse_pivots: Any, rhs: Any) -> Any:
    """In compiled code: :func:`band_ldlt_solve_lanes` without its shape checks (the caller
    allocates the arrays). Typing refuses other than the arrays :func:`_lane_arrays_ok` names."""
    if not _lane_arrays_ok(band, inverse_pivots, rhs):
        return None
    signature = types.void(band, inverse_pivots, rhs)

    def codegen(context: Any, builder: ir.IRBuilder, sig: Any, args: Any) -> None:
        b = BAND
        width = b + 1
        f64 = ir.DoubleType()
        vector = ir.VectorType(f64, LANES)
        pointer = vector.as_pointer()
        intp = context.get_value_type(types.intp)
        band_array = context.make_array(sig.args[0])(context, builder, args[0])
        pivot_array = context.make_array(sig.args[1])(context, builder, args[1])
        rhs_array = context.make_array(sig.args[2])(context, builder, args[2])
        n_rows = builder.extract_value(band_array.shape, 0)

        def const(value: int) -> ir.Constant:
            return ir.Constant(intp, value)

        def at(data: ir.Value, index: ir.Value) -> ir.Value:
            element = builder.gep(data, [builder.mul(index, const(LANES))], inbounds=True)
            return builder.bitcast(element, pointer)

        def band_at(row: ir.Value, s: int) -> ir.Value:
            return at(band_array.data, builder.add(builder.mul(row, const(width)), const(s)))

        def load(address: ir.Value) -> ir.Value:
            return builder.load(address, align=8)

        def store(value: ir.Value, address: ir.Value) -> None:
            builder.store(value, address, align=8)

        def minus_product(total: ir.Value, a: ir.Value, c: ir.Value) -> ir.Value:
            """total - a c, rounded once (the scalar kernel's contracted ``s -= a * c``)."""
            return builder.call(fma, [builder.fsub(negative_zero, a), c, total])

        one = ir.Constant(vector, [1.0] * LANES)
        negative_zero = ir.Constant(vector, [-0.0] * LANES)  # -0 - a = -a, exactly
        fma = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(vector, [vector] * 3), f"llvm.fma.v{LANES}f64"
        )
        start, stop = const(b), builder.sub(n_rows, const(b))
        # Factorisation, column by column (as _band_ldlt_solve).
        with cgutils.for_range_slice(builder, start, stop, const(1), inc=True) as (j, _):
            lower = [load(band_at(j, p)) for p in range(b + 1)]  # A[j, j-p], then L[j, j-p]
            w = [None] + [
                builder.fmul(lower[p], load(band_at(builder.sub(j, const(p)), 0)))
                for p in range(1, b + 1)
            ]
            pivot = lower[0]
            for p in range(b, 0, -1):
                pivot = minus_product(pivot, lower[p], w[p])
            store(pivot, band_at(j, 0))
            inverse = builder.fdiv(one, pivot)
            store(inverse, at(pivot_array.data, j))
            for m in range(1, b + 1):
                i = builder.add(j, const(m))
                s = load(band_at(i, m))
                for p in range(b - m, 0, -1):
                    s = minus_product(s, load(band_at(i, m + p)), w[p])
                store(builder.fmul(s, inverse), band_at(i, m))
        # Forward substitution, L y = rhs.
        with cgutils.for_range_slice(builder, start, stop, const(1), inc=True) as (i, _):
            s = load(at(rhs_array.data, i))
            for p in range(b, 0, -1):
                s = minus_product(
                    s, load(band_at(i, p)), load(at(rhs_array.data, builder.sub(i, const(p))))
                )
            store(s, at(rhs_array.data, i))
        # Diagonal, z = D^-1 y.
        with cgutils.for_range_slice(builder, start, stop, const(1), inc=True) as (i, _):
            address = at(rhs_array.data, i)
            store(builder.fmul(load(address), load(at(pivot_array.data, i))), address)
        # Back substitution, L^T x = z, from the last row up.
        with cgutils.for_range_slice(builder, start, stop, const(1), inc=True) as (k, _):
            i = builder.sub(builder.add(start, builder.sub(stop, const(1))), k)
            s = load(at(rhs_array.data, i))
            for p in range(b, 0, -1):
                row = builder.add(i, const(p))
                s = minus_product(s, load(band_at(row, p)), load(at(rhs_array.data, row)))
            store(s, at(rhs_array.data, i))

    return signature, codegen


@njit(cache=True)
def band_ldlt_solve_lanes(band: Any, inverse_pivots: Any, rhs: Any) -> None:
    """Solve LANES symmetric banded systems in place, lane by lane as
    :func:`jellysim.tentacle.kernels._band_ldlt_solve` solves one: ``band`` (N, BAND + 1, LANES),
    ``inverse_pivots`` and ``rhs`` (N, LANES), with BAND zero rows of padding before and after
    the systems. A lane whose system is singular gives non-finite values in that lane only."""
    if band.shape[1] != BAND + 1 or band.shape[2] != LANES:
        raise ValueError("band must be (N, BAND + 1, LANES)")
    n = band.shape[0]
    if inverse_pivots.shape[0] != n or rhs.shape[0] != n:
        raise ValueError("inverse_pivots and rhs must have the band's rows")
    if inverse_pivots.shape[1] != LANES or rhs.shape[1] != LANES:
        raise ValueError("inverse_pivots and rhs must be (N, LANES)")
    if n < 2 * BAND:
        raise ValueError("the band needs BAND rows of padding before and after")
    _band_ldlt_solve_lanes(band, inverse_pivots, rhs)  # type: ignore[call-arg]
