"""Anti-lag: shorten the history where the lighting changed (runs between reprojection and
accumulation).

SVGF rejects history only with geometric tests, so a moving light, a moving shadow, a
dimmed light or a sliding reflection keeps its stale colour for about 1/alpha frames. This
stage compares, per signal, the reprojected history with the current frame in a
(2r+1)^2 window around every pixel, over the pixels that have history:

* ``m_c``, ``m_h``: window means of the current and of the history luminance;
* ``var``: the per-sample noise variance of the current luminance, the larger of the
  window's sample variance (Bessel-corrected) and the mean temporal variance
  ``m2 - m1^2`` carried by the history moments (a few 1-spp samples often miss the
  outliers that a long history has seen);
* the history is stale where ``(m_h - m_c)^2 > k^2 var / n + (tolerance * max(m_c, m_h))^2``:
  more than ``k`` standard errors of ``m_c`` (``sigma``) plus a small relative tolerance;
* there, ``b^2 = (m_h - m_c)^2 - var / n`` (an unbiased estimate of the history's squared
  bias) and ``lambda = b^2 / (b^2 + var / N)``: the blend weight of the current frame that
  minimises the expected squared error of the filtered result, ``(1 - a)^2 b^2 +
  a^2 var / N``, where ``N`` (``spatial_samples``) is the number of pixels the spatial filter
  averages; elsewhere ``lambda = 0``.

``lambda`` is dilated by a 3x3 maximum (a change seen by a window reaches its border pixels)
and lowers the history length to ``h <= 1/lambda - 1``, so the accumulation's blend factor
``max(alpha, 1/(h + 1))`` is at least ``lambda`` and the moments follow (``lambda = 1``
drops the history and the variance falls back to the spatial estimate). Every term scales
with the signal, so the test is the same at any exposure. Nothing changes where the
difference is within the noise: at 1 spp the test is conservative, where the change is real
it is decisive.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from svgf_cli.filters.fastmath import FASTMATH

F32 = np.float32
_ZERO = F32(0.0)
_ONE = F32(1.0)
# Fewer pixels with history than this in a window: no decision (the statistics are noise).
MIN_SAMPLES = 4
# Window sums: valid count, sum l, sum l^2, sum history l, sum temporal variance.
_TERMS = 5

_JIT = dict(fastmath=FASTMATH, cache=True, nogil=True, boundscheck=False, error_model="numpy")


def antilag(
    illumination: np.ndarray,
    history_illumination: np.ndarray,
    history_moments: np.ndarray,
    history_length: np.ndarray,
    depth: np.ndarray,
    luminance_weights: np.ndarray,
    radius: int,
    sigma: float,
    spatial_samples: float,
    tolerance: float,
    scratch: np.ndarray,
    out_lambda: np.ndarray,
) -> int:
    """Lower ``history_length`` (S, H, W) in place where the history disagrees with the frame.

    ``illumination`` and ``history_illumination`` are (S, 3, H, W) (current demodulated
    signal and reprojected history), ``history_moments`` (S, 2, H, W), ``luminance_weights``
    (3,) float32. ``scratch`` is a float32 (5, H, W) buffer, ``out_lambda`` (S, H, W)
    receives the dilated blend weight (0 where the history is kept as it is). Returns the
    number of (signal, pixel) histories that were shortened.
    """
    num_signals = illumination.shape[0]
    shortened = 0
    for s in range(num_signals):
        _window_terms(illumination[s], history_illumination[s], history_moments[s],
                      history_length[s], depth, luminance_weights, np.int64(radius), scratch)
        _blend_weight(scratch, np.int64(radius), F32(sigma), F32(spatial_samples),
                      F32(tolerance), out_lambda[s])
        shortened += int(_dilate_and_shorten(out_lambda[s], history_length[s], scratch[0]))
    return shortened


@njit(parallel=True, **_JIT)
def _window_terms(
    current: np.ndarray,
    history: np.ndarray,
    moments: np.ndarray,
    history_length: np.ndarray,
    depth: np.ndarray,
    weights: np.ndarray,
    radius: int,
    out: np.ndarray,
) -> None:
    """Per-pixel terms over pixels with history, summed along x over ``2r+1`` pixels.

    Running sums are kept in float64 so that adding and removing values along a row does
    not drift.
    """
    height, width = depth.shape
    wr, wg, wb = weights[0], weights[1], weights[2]
    for y in prange(height):
        terms = np.empty((_TERMS, width), dtype=np.float64)
        for x in range(width):
            valid = history_length[y, x] > _ZERO and depth[y, x] > _ZERO
            lum = wr * current[0, y, x] + wg * current[1, y, x] + wb * current[2, y, x]
            lum_h = wr * history[0, y, x] + wg * history[1, y, x] + wb * history[2, y, x]
            m1 = moments[0, y, x]
            temporal = max(moments[1, y, x] - m1 * m1, _ZERO)
            v = 1.0 if valid else 0.0
            terms[0, x] = v
            terms[1, x] = v * lum
            terms[2, x] = v * lum * lum
            terms[3, x] = v * lum_h
            terms[4, x] = v * temporal
        for t in range(_TERMS):
            running = 0.0
            for x in range(min(radius, width)):
                running += terms[t, x]
            for x in range(width):
                if x + radius < width:
                    running += terms[t, x + radius]
                if x - radius - 1 >= 0:
                    running -= terms[t, x - radius - 1]
                out[t, y, x] = running


@njit(parallel=True, **_JIT)
def _blend_weight(
    row_sums: np.ndarray,
    radius: int,
    sigma: np.float32,
    spatial_samples: np.float32,
    tolerance: np.float32,
    out_lambda: np.ndarray,
) -> None:
    """Sum the row sums over ``2r+1`` rows and evaluate the blend weight (module docstring)."""
    height, width = out_lambda.shape
    k2 = sigma * sigma
    tol2 = tolerance * tolerance
    inv_spatial = _ONE / spatial_samples
    for y in prange(height):
        sums = np.zeros((_TERMS, width), dtype=np.float32)
        for yy in range(max(y - radius, 0), min(y + radius + 1, height)):
            for t in range(_TERMS):
                row = row_sums[t, yy]
                acc = sums[t]
                for x in range(width):
                    acc[x] += row[x]
        out = out_lambda[y]
        for x in range(width):
            n = sums[0, x]
            inv_n = _ONE / max(n, _ONE)
            mean_c = sums[1, x] * inv_n
            mean_h = sums[3, x] * inv_n
            spread = max(sums[2, x] * inv_n - mean_c * mean_c, _ZERO)
            sample_var = spread * n / max(n - _ONE, _ONE)
            var = max(sample_var, sums[4, x] * inv_n)
            diff = mean_h - mean_c
            level = max(mean_c, mean_h)
            diff2 = diff * diff
            standard_error2 = var * inv_n
            significant = diff2 > k2 * standard_error2 + tol2 * level * level
            bias2 = diff2 - standard_error2
            noise = var * inv_spatial
            lam = bias2 / (bias2 + noise) if significant else _ZERO
            out[x] = lam if n >= F32(MIN_SAMPLES) else _ZERO


@njit(parallel=True, **_JIT)
def _dilate_and_shorten(
    lam: np.ndarray, history_length: np.ndarray, scratch: np.ndarray
) -> int:
    """3x3 maximum of ``lam`` (in place, via ``scratch``), then ``h = min(h, 1/lam - 1)``."""
    height, width = lam.shape
    for y in prange(height):
        for x in range(width):
            best = lam[y, x]
            if x > 0:
                best = max(best, lam[y, x - 1])
            if x + 1 < width:
                best = max(best, lam[y, x + 1])
            scratch[y, x] = best
    count = 0
    for y in prange(height):
        row_count = 0
        for x in range(width):
            best = scratch[y, x]
            if y > 0:
                best = max(best, scratch[y - 1, x])
            if y + 1 < height:
                best = max(best, scratch[y + 1, x])
            h = history_length[y, x]
            keep = h > _ZERO and best > _ZERO
            lam[y, x] = best if keep else _ZERO
            if keep:
                limit = max(_ONE / best - _ONE, _ZERO)
                if limit < h:
                    history_length[y, x] = limit
                    row_count += 1
        count += row_count
    return count
