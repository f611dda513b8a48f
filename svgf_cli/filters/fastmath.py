"""Scalar helpers shared by the kernels: float32 constants, luminance and a vectorizable exp.

``math.exp`` compiles to a scalar libm call that blocks SIMD in numba loops (no SVML here).
``fast_exp`` splits ``x * log2(e)`` into integer and fraction, evaluates ``2**fraction`` with
a degree-5 polynomial (relative error < 1e-7, fitted for this project) and builds ``2**integer``
directly from the IEEE-754 exponent bits, so a loop calling it stays branch-free and vectorizes.
"""

from __future__ import annotations

import llvmlite.ir as llvm_ir
import numpy as np
from numba import njit, types
from numba.extending import intrinsic

F32 = np.float32

# Rec.709 luminance weights (the paper's l(.)).
LUMA_R = F32(0.2126)
LUMA_G = F32(0.7152)
LUMA_B = F32(0.0722)

_LOG2E = F32(1.4426950408889634)
_EXP2_MIN = F32(-125.0)
_EXP2_MAX = F32(127.0)
# 2**f on [0, 1]: least squares on relative error with the constant pinned to 1.
_C1 = F32(0.69315136)
_C2 = F32(0.24016414)
_C3 = F32(0.05580049)
_C4 = F32(0.00901663)
_C5 = F32(0.00186721)
_ONE = F32(1.0)


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


@njit(inline="always", fastmath=True, cache=True, error_model="numpy")
def fast_exp(x: np.float32) -> np.float32:
    """exp(x) for float32 x (accurate to ~1e-7 relative; underflows to ~1e-38 below -86)."""
    t = x * _LOG2E
    t = min(max(t, _EXP2_MIN), _EXP2_MAX)
    whole = np.floor(t)
    frac = t - whole
    poly = _ONE + frac * (_C1 + frac * (_C2 + frac * (_C3 + frac * (_C4 + frac * _C5))))
    bits = (np.int32(whole) + 127) << 23
    return poly * _int32_bits_as_float32(bits)


@njit(inline="always", fastmath=True, cache=True, error_model="numpy")
def luminance(r: np.float32, g: np.float32, b: np.float32) -> np.float32:
    """Rec.709 luminance of one linear RGB value."""
    return LUMA_R * r + LUMA_G * g + LUMA_B * b
