"""Sharp history resampling: a clamped Catmull-Rom fetch of the reprojected history.

Each frame the reprojection resamples the history at a sub-pixel position. Bilinear
interpolation is a low-pass filter (at a half-pixel offset it halves the highest frequency's
amplitude), and the history is resampled again every frame, so over the ~1/alpha frames a
pixel's history averages the blur compounds: the history carries a bias toward a blurred
image that grows with its length (TAA's known softening). Measured on the bundled
sequences with camera motion (the noise-free references accumulated through the frames'
motion, docs/algorithm.md), the history's error against the current reference was 9-19 %
lower with this fetch at alpha 0.2 and grew by 60-70 % from alpha 0.2 to 0.1 with bilinear.
Bilinear's averaging also removes noise, which the spline keeps more of: it pays on a
history with little noise (the temporal albedo's colour means: on in ``default``), not on
the noisy colour accumulation (``history_catmull_rom``: off; docs/algorithm.md).

The fetch is the Catmull-Rom spline (Keys' cubic convolution with ``a = -1/2``), separable
over the 4x4 taps around the position ``(x0 + fx, y0 + fy)``: per axis, with ``t`` the
fraction, the weights of the taps at offsets -1, 0, 1, 2 are

    w0 = t (-1/2 + t (1 - t/2)),  w1 = 1 + t^2 (-5/2 + 3t/2),
    w2 = t (1/2 + t (2 - 3t/2)),  w3 = t^2 (-1/2 + t/2)

(they sum to 1; at ``t = 0`` they are 0, 1, 0, 0: an axis without a fraction uses the one
column or row). The spline interpolates (a tap's own value at ``t = 0``) and reproduces
linear ramps exactly, so it does not blur them; its negative lobes overshoot at edges, so the
result is clamped per channel to the range of the inner 2x2 taps with weight (the bilinear
cell: the "anti-ringing" bound of video scalers, stricter than the range of all 16), which
also keeps a non-negative history non-negative and a constant one constant. The luminance
moments are fetched the same way, and the second is raised to at least the square of the
first (their variance stays non-negative).

:func:`catmull_rom_weights` is the per-axis weight; :func:`catmull_rom_history` one
signal's colour and moments at one pixel from the taps the reprojection chose
(``reproject``: the spline is used only where every tap of the support passed the same
consistency tests as the bilinear taps; elsewhere the renormalised bilinear fetch stays);
:func:`clamped_catmull_rom` the three channels of a (3, H, W) history at one position (the
temporal albedo's colour means, ``albedo_history``, under the same rule with its tests).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from svgf_cli.filters.fastmath import FASTMATH

F32 = np.float32
U = np.uint64
_ZERO = F32(0.0)
_HALF = F32(0.5)
_ONE = F32(1.0)
# Not inlined at numba's level: LLVM still inlines where it pays, and the kernels that call
# these compile much faster from a cold cache (measured: the same 1080p speed, 15 s less).
_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")


@njit(**_JIT)
def catmull_rom_weights(
    t: np.float32,
) -> tuple[np.float32, np.float32, np.float32, np.float32]:
    """The Catmull-Rom weights of the taps at offsets -1, 0, 1, 2 for fraction ``t`` in
    [0, 1) (module docstring)."""
    w0 = t * (-_HALF + t * (_ONE - _HALF * t))
    w1 = _ONE + t * t * (F32(-2.5) + F32(1.5) * t)
    w2 = t * (_HALF + t * (F32(2.0) - F32(1.5) * t))
    w3 = t * t * (-_HALF + _HALF * t)
    return w0, w1, w2, w3


@njit(**_JIT)
def _clamped_fetch(
    history: np.ndarray, s: int, c: int, rows: np.ndarray, columns: np.ndarray,
    weights: np.ndarray, x: np.uint64,
) -> np.float32:
    """``sum_j wy_j sum_i wx_i history[s, c, rows_j, columns_i]`` clamped to the range of
    the inner taps (rows 1, 2 x columns 1, 2). ``rows[:, x]``, ``columns[:, x]`` hold the
    support's indices, ``weights[0:4, x]`` the column weights and ``weights[4:8, x]`` the row
    weights. Indexes the 4-D array directly (a per-pixel view would cost an atomic
    reference-count update, contended between threads)."""
    total = _ZERO
    for j in range(4):
        r = rows[j, x]
        across = (
            weights[0, x] * history[s, c, r, columns[0, x]]
            + weights[1, x] * history[s, c, r, columns[1, x]]
            + weights[2, x] * history[s, c, r, columns[2, x]]
            + weights[3, x] * history[s, c, r, columns[3, x]]
        )
        total += weights[4 + j, x] * across
    a = history[s, c, rows[1, x], columns[1, x]]
    b = history[s, c, rows[1, x], columns[2, x]]
    d = history[s, c, rows[2, x], columns[1, x]]
    e = history[s, c, rows[2, x], columns[2, x]]
    lo = min(min(a, b), min(d, e))
    hi = max(max(a, b), max(d, e))
    return min(max(total, lo), hi)


@njit(**_JIT)
def catmull_rom_history(
    s: int, uy: np.uint64, ux: np.uint64, rows: np.ndarray, columns: np.ndarray,
    weights: np.ndarray, prev_illumination: np.ndarray, prev_moments: np.ndarray,
    out_illumination: np.ndarray, out_moments: np.ndarray,
) -> None:
    """Signal ``s``'s colour and moments at pixel ``(ux, uy)``: the clamped Catmull-Rom
    fetch (:func:`_clamped_fetch`) of every channel, then ``m2 = max(m2, m1^2)``. The
    support of column ``ux`` of the row is in ``rows``, ``columns`` (4, W) and its weights
    in ``weights`` (8, W)."""
    for c in range(3):
        out_illumination[s, c, uy, ux] = _clamped_fetch(
            prev_illumination, s, c, rows, columns, weights, ux)
    m1 = _clamped_fetch(prev_moments, s, 0, rows, columns, weights, ux)
    m2 = _clamped_fetch(prev_moments, s, 1, rows, columns, weights, ux)
    out_moments[s, 0, uy, ux] = m1
    out_moments[s, 1, uy, ux] = max(m2, m1 * m1)


@njit(**_JIT)
def _row_sum(
    history: np.ndarray, c: int, r: np.uint64, xa: np.uint64, xb: np.uint64, xc: np.uint64,
    xd: np.uint64, wx0: np.float32, wx1: np.float32, wx2: np.float32, wx3: np.float32,
) -> np.float32:
    """One row of the 4x4 sum: ``sum_i wx_i history[c, r, x_i]``."""
    return (wx0 * history[c, r, xa] + wx1 * history[c, r, xb] + wx2 * history[c, r, xc]
            + wx3 * history[c, r, xd])


@njit(**_JIT)
def clamped_catmull_rom(
    history: np.ndarray, x0: int, y0: int, fx: np.float32, fy: np.float32,
) -> tuple[np.float32, np.float32, np.float32]:
    """The three channels of ``history`` (a (3, H, W) array) at ``(x0 + fx, y0 + fy)``: the
    Catmull-Rom sum over the support (one column where ``fx`` is 0, one row where ``fy``
    is), clamped per channel to the range of the bilinear taps with weight. The caller
    checked every tap is inside.

    The same sum and clamp as :func:`_clamped_fetch`, with the support in scalars shared by
    the three channels: going through the support arrays measured 60 against 38 ms a
    frame for the temporal albedo at 1080p with every pixel at a sub-pixel position."""
    wx0, wx1, wx2, wx3 = catmull_rom_weights(fx)
    wy0, wy1, wy2, wy3 = catmull_rom_weights(fy)
    # An axis without a fraction: every column (row) is the one tap, weights 0, 1, 0, 0.
    xa = U(x0 - 1) if fx > _ZERO else U(x0)
    xb = U(x0)
    xc = U(x0 + 1) if fx > _ZERO else U(x0)
    xd = U(x0 + 2) if fx > _ZERO else U(x0)
    ya = U(y0 - 1) if fy > _ZERO else U(y0)
    yb = U(y0)
    yc = U(y0 + 1) if fy > _ZERO else U(y0)
    yd = U(y0 + 2) if fy > _ZERO else U(y0)
    out_r = _ZERO
    out_g = _ZERO
    out_b = _ZERO
    for c in range(3):
        total = (wy0 * _row_sum(history, c, ya, xa, xb, xc, xd, wx0, wx1, wx2, wx3)
                 + wy1 * _row_sum(history, c, yb, xa, xb, xc, xd, wx0, wx1, wx2, wx3)
                 + wy2 * _row_sum(history, c, yc, xa, xb, xc, xd, wx0, wx1, wx2, wx3)
                 + wy3 * _row_sum(history, c, yd, xa, xb, xc, xd, wx0, wx1, wx2, wx3))
        a = history[c, yb, xb]
        b = history[c, yb, xc]
        d = history[c, yc, xb]
        e = history[c, yc, xc]
        value = min(max(total, min(min(a, b), min(d, e))), max(max(a, b), max(d, e)))
        if c == 0:
            out_r = value
        elif c == 1:
            out_g = value
        else:
            out_b = value
    return out_r, out_g, out_b
