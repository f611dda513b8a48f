"""Scalar helpers shared by the kernels: float32 constants, luminance and a vectorizable exp.

``math.exp`` compiles to a scalar libm call that blocks SIMD in numba loops (no SVML here).
``fast_exp`` handles what the edge-stopping weights need, ``exp(x)`` for ``x <= 0``: it
splits ``t = x * log2(e)`` into its integer part (truncation, no rounding instruction) and
fraction ``f`` in (-1, 0], evaluates ``2**f`` with a degree-4 polynomial (relative error
< 4e-6, fitted for this project) and builds ``2**integer`` from the IEEE-754 exponent bits,
so a loop calling it stays branch-free and vectorizes.
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

# Rec.709 luminance weights (the paper's l(.)).
LUMA_R = F32(0.2126)
LUMA_G = F32(0.7152)
LUMA_B = F32(0.0722)

_LOG2E = F32(1.4426950408889634)
_EXP2_MIN = F32(-126.0)
_ZERO = F32(0.0)
# 2**f on [-1, 0]: least squares on relative error with the constant pinned to 1.
_C1 = F32(0.6930601)
_C2 = F32(0.23943874)
_C3 = F32(0.05319557)
_C4 = F32(0.00681833)
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


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def fast_exp(x: np.float32) -> np.float32:
    """exp(x) for float32 ``x <= 0`` (positive x is treated as 0; below -87 gives ~1e-38)."""
    t = min(max(x * _LOG2E, _EXP2_MIN), _ZERO)
    whole = np.int32(t)  # truncates toward zero, so frac lies in (-1, 0]
    frac = t - np.float32(whole)
    poly = _ONE + frac * (_C1 + frac * (_C2 + frac * (_C3 + frac * _C4)))
    bits = (whole + 127) << 23
    return poly * _int32_bits_as_float32(bits)


@njit(inline="always", fastmath=FASTMATH, cache=True, nogil=True, error_model="numpy")
def luminance(r: np.float32, g: np.float32, b: np.float32) -> np.float32:
    """Rec.709 luminance of one linear RGB value."""
    return LUMA_R * r + LUMA_G * g + LUMA_B * b
