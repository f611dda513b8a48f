"""Scalar helpers shared by the kernels: float32 constants, luminance and a vectorizable exp.

``math.exp`` compiles to a scalar libm call that blocks SIMD in numba loops (no SVML here).
``fast_exp`` handles what the edge-stopping weights need, ``exp(x)`` for ``x <= 0``: it
splits ``t = x * log2(e)`` into its integer part (truncation, no rounding instruction) and
fraction ``f`` in (-1, 0], evaluates ``2**f`` with a degree-4 polynomial (relative error
< 4e-6, fitted for this project) and builds ``2**integer`` from the IEEE-754 exponent bits,
so a loop calling it stays branch-free and vectorizes. ``fast_log2`` is the mirror image
(exponent bits plus a degree-7 polynomial for the mantissa, absolute error < 1e-6); the
a-trous uses it to fold ``cos ** sigma_n`` into its single exp.
"""

from __future__ import annotations

import llvmlite.ir as llvm_ir
import numpy as np
from numba import njit, types
from numba.extending import intrinsic

F32 = np.float32

# The fast-math flags every kernel compiles with. Not numba's fastmath=FASTMATH: its "arcp"
# (reciprocal approximation), "reassoc" and "contract" let LLVM pick different instructions for
# the same source, and measured here a process that JIT-compiled the kernels gave outputs 1 ulp
# away from a process that loaded them from numba's cache (thousands of pixels from frame 3
# on). These three flags keep vectorization (the loops are element-wise, no reductions) and
# make every build of a kernel round identically, so outputs are bit-identical run to run.
FASTMATH = {"nnan", "ninf", "nsz"}

# Rec.709 luminance weights (the paper's l(.)), the default of Frame.luminance_weights.
REC709 = (F32(0.2126), F32(0.7152), F32(0.0722))

_LOG2E = F32(1.4426950408889634)
_EXP2_MIN = F32(-126.0)
# fast_exp gives exactly 0 at or below 2**-50 (x <= -34.66). The weights it makes are summed
# with a centre weight of at least 9/64, so what is flushed is 14 orders of magnitude below
# float32's resolution of the sum; without the flush, tiny weights (a depth step of a fog
# pixel's 1e10 "no surface" next to a wall) went on into products below 2**-126, subnormal
# numbers, which the CPU handles in microcode: the a-trous measured 5-8x slower per
# iteration on a 1080p frame of random depths (bench numbers in docs/performance.md).
_EXP2_FLUSH = F32(-50.0)
_ZERO = F32(0.0)
# 2**f on [-1, 0]: least squares on relative error with the constant pinned to 1.
_C1 = F32(0.6930601)
_C2 = F32(0.23943874)
_C3 = F32(0.05319557)
_C4 = F32(0.00681833)
_ONE = F32(1.0)
# log2(1 + t) on t in [0, 1): least squares on absolute error with log2(1) = 0 pinned.
_L1 = F32(1.4426592588424683)
_L2 = F32(-0.7204583883285522)
_L3 = F32(0.47289368510246277)
_L4 = F32(-0.3242958188056946)
_L5 = F32(0.19230864942073822)
_L6 = F32(-0.07835815101861954)
_L7 = F32(0.015251433476805687)
_MANTISSA_MASK = np.int32(0x007FFFFF)
_ONE_BITS = np.int32(0x3F800000)


@intrinsic
def _int32_bits_as_float32(typingctx, bits):  # type: ignore[no-untyped-def]
    """Reinterpret the low 32 bits of an integer as float32 (an LLVM bitcast; vectorizes)."""
    if not isinstance(bits, types.Integer):
        return None
    signature = types.float32(bits)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        value = args[0]
        if sig.args[0].bitwidth != 32:
            value = builder.trunc(value, llvm_ir.IntType(32))
        return builder.bitcast(value, llvm_ir.FloatType())

    return signature, codegen


@intrinsic
def fma(typingctx, a, b, c):  # type: ignore[no-untyped-def]
    """``a * b + c`` rounded once (``llvm.fma.f32``; one vfmadd instruction, vectorizes).

    Explicit, unlike letting LLVM contract ``a * b + c`` under a fast-math flag: whether a
    contraction happens would depend on how the code was inlined, which differs between a
    fresh compile and a cache load (see ``FASTMATH``); an explicit fma rounds the same way in
    every build.
    """
    if not (a == b == c == types.float32):
        return None
    signature = types.float32(types.float32, types.float32, types.float32)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        f32 = llvm_ir.FloatType()
        function = builder.module.declare_intrinsic(
            "llvm.fma", [f32], llvm_ir.FunctionType(f32, [f32, f32, f32])
        )
        return builder.call(function, args)

    return signature, codegen


@intrinsic
def float32_bits(typingctx, value):  # type: ignore[no-untyped-def]
    """Reinterpret a float32 as its 32 IEEE-754 bits (an LLVM bitcast; vectorizes)."""
    if value != types.float32:
        return None
    signature = types.int32(value)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
        return builder.bitcast(args[0], llvm_ir.IntType(32))

    return signature, codegen


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def fast_log2(x: np.float32) -> np.float32:
    """log2(x) for finite float32 ``x > 0`` (normal numbers; absolute error < 1e-6)."""
    bits = float32_bits(x)
    # Not named like any caller's variable: numba's inline="always" can let an inlined
    # callee's local overwrite a caller's variable of the same name (seen with "exponent").
    log2_whole = np.float32((bits >> 23) - 127)
    t = _int32_bits_as_float32((bits & _MANTISSA_MASK) | _ONE_BITS) - _ONE
    poly = fma(t, fma(t, fma(t, fma(t, fma(t, _L7, _L6), _L5), _L4), _L3), _L2)
    return fma(t, fma(t, poly, _L1), log2_whole)


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def fast_exp(x: np.float32) -> np.float32:
    """exp(x) for float32 ``x <= 0`` (positive x is treated as 0); 0 where exp(x) <= 2**-50
    (never a subnormal number: see ``_EXP2_FLUSH``)."""
    t = min(max(x * _LOG2E, _EXP2_MIN), _ZERO)
    whole = np.int32(t)  # truncates toward zero, so frac lies in (-1, 0]
    frac = t - np.float32(whole)
    poly = fma(frac, fma(frac, fma(frac, fma(frac, _C4, _C3), _C2), _C1), _ONE)
    bits = (whole + 127) << 23
    value = poly * _int32_bits_as_float32(bits)
    return value if t > _EXP2_FLUSH else _ZERO


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def luminance(
    r: np.float32, g: np.float32, b: np.float32, weights: tuple[np.float32, np.float32, np.float32]
) -> np.float32:
    """Luminance ``w_r r + w_g g + w_b b`` of one linear RGB value (``weights`` from the
    frame's colour space; summed in this order, so Rec.709 weights reproduce the former
    constants bit for bit)."""
    return weights[0] * r + weights[1] * g + weights[2] * b


def float32_weights(weights: tuple[float, float, float]) -> tuple[F32, F32, F32]:
    """The float32 triple every kernel takes (one numba signature for all callers)."""
    return (F32(weights[0]), F32(weights[1]), F32(weights[2]))
